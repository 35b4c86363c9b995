"""Readout electronics: taxel columns in parallel -> Wheatstone bridge -> in-amp -> ADC -> digital Butterworth.

Source: cnt_pdms sect. 2.2 (bridge + in-amp, 14-bit NI USB-6009 at 100 Hz, 4th-order 10 Hz Butterworth);
bridge in exact form V = V_ex (R_s / (R_s + R_b) - 1/2) (Horowitz & Hill, The Art of Electronics, 3rd ed.).
Numpy reference and Warp kernels side by side; the electronics run in float64 on both so ADC codes agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from sensors.params import ElectronicsParams

MAX_SECTIONS = 4  # 8th-order filter at most (ElectronicsConfig.filter_order <= 8)
vec_sos = wp.types.vector(length=6 * MAX_SECTIONS, dtype=wp.float64)
vec_zi = wp.types.vector(length=2 * MAX_SECTIONS, dtype=wp.float64)


@dataclass
class ElectronicsState:
    """Filter state per (episode, channel): [B, 2*MAX_SECTIONS] float64, and whether it was primed."""

    filt: np.ndarray
    primed: np.ndarray  # [B] int32

    @classmethod
    def zeros(cls, n: int) -> "ElectronicsState":
        return cls(np.zeros((n, 2 * MAX_SECTIONS)), np.zeros(n, np.int32))


def pink_noise(rng: np.random.Generator, shape: tuple[int, ...], rms: float) -> np.ndarray:
    """1/f (pink) noise along the last axis by spectral shaping of white noise, scaled to `rms` (float64)."""
    n = shape[-1]
    if rms == 0.0 or n < 2:
        return np.zeros(shape)
    spec = np.fft.rfft(rng.standard_normal(shape), axis=-1)
    f = np.arange(spec.shape[-1], dtype=float)
    f[0] = 1.0
    spec /= np.sqrt(f)
    spec[..., 0] = 0.0
    x = np.fft.irfft(spec, n=n, axis=-1)
    x /= max(float(x.std()), 1e-30)
    return x * rms


def readout_noise_v(seed: int, n_steps: int, n_channels: int, white_v: float, pink_v: float) -> np.ndarray:
    """Noise at the ADC input for one episode, [T, C] float64, from the episode's own seed (stream 1)."""
    rng = np.random.default_rng([seed, 1])
    white = rng.standard_normal((n_channels, n_steps)) * white_v
    return (white + pink_noise(rng, (n_channels, n_steps), pink_v)).T


def readout_noise_batch(seeds: list[int], n_steps: int, n_channels: int, white_v: float, pink_v: float) -> np.ndarray:
    """[E, T, C] float64: `readout_noise_v` of every episode (same values), drawn on a thread pool for large
    batches (numpy's generators and FFT release the GIL; each episode has its own generator)."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    out = np.empty((len(seeds), n_steps, n_channels))

    def fill(i: int) -> None:
        out[i] = readout_noise_v(seeds[i], n_steps, n_channels, white_v, pink_v)

    workers = min(8, os.cpu_count() or 1)
    if len(seeds) * n_steps * n_channels < 2_000_000 or workers == 1:
        for i in range(len(seeds)):
            fill(i)
    else:
        with ThreadPoolExecutor(workers, thread_name_prefix="noise") as pool:
            list(pool.map(fill, range(len(seeds))))
    return out


def _sos_vectors(ep: ElectronicsParams) -> tuple[np.ndarray, np.ndarray, int]:
    ns = ep.sos.shape[0]
    if ns > MAX_SECTIONS:
        raise ValueError(f"filter has {ns} sections; at most {MAX_SECTIONS} supported")
    sos = np.zeros((MAX_SECTIONS, 6))
    sos[:, 0] = 1.0
    sos[:, 3] = 1.0
    sos[:ns] = ep.sos
    zi = np.zeros((MAX_SECTIONS, 2))
    zi[:ns] = ep.sos_zi
    return sos.reshape(-1), zi.reshape(-1), ns


# ----------------------------------------------------------------------------------------------- numpy


def sum_channels_numpy(cond_s: np.ndarray, stress_pa: np.ndarray, taxel_channel: np.ndarray, n_channels: int, area_m2: float):
    """[E,T,N] taxel conductance and stress -> channel conductance [E,T,C] (parallel columns) and total force [E,T] (N)."""
    E, T, _ = cond_s.shape
    g = np.zeros((E, T, n_channels))
    for c in range(n_channels):
        g[..., c] = cond_s[..., taxel_channel == c].astype(np.float64).sum(-1)
    force = stress_pa.astype(np.float64).sum(-1) * area_m2
    return g, force


def readout_numpy(g_s: np.ndarray, noise_v: np.ndarray, ep: ElectronicsParams, state: ElectronicsState | None = None):
    """Channel conductance [E,T,C] + noise [E,T,C] -> dict of [E,T,C] arrays (resistance, bridge_v, adc, filtered_v,
    resistance_measured). Float64; the filter is a transposed direct-form-II cascade primed at the first sample."""
    E, T, C = g_s.shape
    st = state or ElectronicsState.zeros(E * C)
    sos, zi_unit, ns = _sos_vectors(ep)
    sos = sos.reshape(MAX_SECTIONS, 6)
    zi_unit = zi_unit.reshape(MAX_SECTIONS, 2)
    z = st.filt.reshape(E, C, MAX_SECTIONS, 2).copy()
    primed = st.primed.reshape(E, C).copy()
    r_s = 1.0 / g_s
    vb = ep.excitation_v * (r_s / (r_s + ep.bridge_resistance_ohm) - 0.5)
    v = ep.amp_gain * vb + ep.amp_offset_v + noise_v
    code = np.clip(np.rint(v / ep.lsb_v), ep.code_min, ep.code_max)
    v_adc = code * ep.lsb_v
    y_all = np.empty_like(v_adc)
    for k in range(T):
        x = v_adc[:, k, :]
        fresh = primed == 0
        if fresh.any():
            z[fresh] = zi_unit[None, :, :] * x[fresh][:, None, None]
            primed[fresh] = 1
        for i in range(ns):
            b0, b1, b2, _, a1, a2 = sos[i]
            y = b0 * x + z[:, :, i, 0]
            z[:, :, i, 0] = b1 * x - a1 * y + z[:, :, i, 1]
            z[:, :, i, 1] = b2 * x - a2 * y
            x = y
        y_all[:, k, :] = x
    ratio = (y_all - ep.amp_offset_v) / ep.amp_gain / ep.excitation_v + 0.5
    r_meas = ep.bridge_resistance_ohm * ratio / (1.0 - ratio)
    out = {"resistance": r_s, "bridge_v": vb, "adc": code.astype(np.int32), "filtered_v": y_all, "resistance_measured": r_meas}
    return out, ElectronicsState(z.reshape(E * C, -1), primed.reshape(-1))


# ------------------------------------------------------------------------------------------------ warp


REDUCE_BLOCK = 256  # threads per (episode, step) row in the tiled channel sum on CUDA (Warp uses 1 on the CPU)


@wp.kernel
def sum_channels_kernel(
    cond: wp.array(dtype=wp.float32),  # [E*T*N]
    stress: wp.array(dtype=wp.float32),  # [E*T*N]
    taxel_channel: wp.array(dtype=wp.int32),  # [N]
    n_taxels: int,
    n_channels: int,
    area: float,
    g_out: wp.array(dtype=wp.float64),  # [E*T*C]
    force_out: wp.array(dtype=wp.float64),  # [E*T]
):
    # one block per (episode, step) row; lanes stride over the taxels (coalesced loads), then a fixed-order
    # tile reduction: deterministic on each device, and CPU vs CUDA differ only by float64 rounding
    et, lane = wp.tid()
    base = et * n_taxels
    nb = wp.block_dim()
    f = wp.float64(0.0)
    for j in range(lane, n_taxels, nb):
        f += wp.float64(stress[base + j])
    ft = wp.tile_sum(wp.tile(f))
    if lane == 0:
        force_out[et] = wp.tile_extract(ft, 0) * wp.float64(area)
    for c in range(n_channels):
        g = wp.float64(0.0)
        for j in range(lane, n_taxels, nb):
            if taxel_channel[j] == c:
                g += wp.float64(cond[base + j])
        gt = wp.tile_sum(wp.tile(g))
        if lane == 0:
            g_out[et * n_channels + c] = wp.tile_extract(gt, 0)


@wp.kernel
def readout_kernel(
    g: wp.array(dtype=wp.float64),  # [E*T*C]
    noise: wp.array(dtype=wp.float64),  # [E*T*C]
    n_steps: int,
    n_channels: int,
    n_sections: int,
    sos: vec_sos,
    zi_unit: vec_zi,
    v_ex: wp.float64,
    r_b: wp.float64,
    gain: wp.float64,
    offset: wp.float64,
    lsb: wp.float64,
    code_min: wp.float64,
    code_max: wp.float64,
    st_filt: wp.array(dtype=vec_zi),  # [E*C]
    st_primed: wp.array(dtype=wp.int32),
    out_r: wp.array(dtype=wp.float64),
    out_vb: wp.array(dtype=wp.float64),
    out_code: wp.array(dtype=wp.int32),
    out_vf: wp.array(dtype=wp.float64),
    out_rm: wp.array(dtype=wp.float64),
):
    tid = wp.tid()  # (episode, channel)
    ep = tid // n_channels
    c = tid - ep * n_channels
    z = st_filt[tid]
    primed = st_primed[tid]
    half = wp.float64(0.5)
    one = wp.float64(1.0)
    for k in range(n_steps):
        idx = (ep * n_steps + k) * n_channels + c
        r_s = one / g[idx]
        vb = v_ex * (r_s / (r_s + r_b) - half)
        v = gain * vb + offset + noise[idx]
        code = wp.min(wp.max(wp.round(v / lsb), code_min), code_max)
        x = code * lsb
        if primed == 0:
            for j in range(2 * MAX_SECTIONS):
                z[j] = zi_unit[j] * x
            primed = 1
        for i in range(MAX_SECTIONS):
            if i < n_sections:
                y = sos[6 * i + 0] * x + z[2 * i + 0]
                z[2 * i + 0] = sos[6 * i + 1] * x - sos[6 * i + 4] * y + z[2 * i + 1]
                z[2 * i + 1] = sos[6 * i + 2] * x - sos[6 * i + 5] * y
                x = y
        ratio = (x - offset) / gain / v_ex + half
        out_r[idx] = r_s
        out_vb[idx] = vb
        out_code[idx] = int(code)
        out_vf[idx] = x
        out_rm[idx] = r_b * ratio / (one - ratio)
    st_filt[tid] = z
    st_primed[tid] = primed


def sum_channels_warp(
    cond: wp.array, stress: wp.array, taxel_channel: np.ndarray, n_channels: int, area_m2: float,
    shape: tuple[int, int, int], device: str,
):
    """Flat [E*T*N] taxel conductance and stress on the device -> channel conductance [E*T*C] and force [E*T]."""
    E, T, N = shape
    g = wp.empty(E * T * n_channels, dtype=wp.float64, device=device)
    force = wp.empty(E * T, dtype=wp.float64, device=device)
    tc = wp.array(np.asarray(taxel_channel, np.int32), dtype=wp.int32, device=device)
    wp.launch_tiled(
        sum_channels_kernel, dim=[E * T], inputs=[cond, stress, tc, N, n_channels, float(area_m2), g, force],
        block_dim=REDUCE_BLOCK if device.startswith("cuda") else 1, device=device,
    )
    return g, force


def readout_warp(
    g: wp.array, shape: tuple[int, int, int], noise_v: np.ndarray, ep: ElectronicsParams,
    state: ElectronicsState | None, device: str, keep=None,
):
    """Channel conductance on the device (flat [E*T*C]) -> (dict of numpy [E,T,C] outputs, state).
    keep: names of the outputs to copy back to the host (default all: resistance, bridge_v, adc,
    filtered_v, resistance_measured)."""
    E, T, C = shape
    d = device
    st = state or ElectronicsState.zeros(E * C)
    sos, zi, ns = _sos_vectors(ep)
    filt = wp.array(st.filt, dtype=vec_zi, device=d)
    primed = wp.array(st.primed, dtype=wp.int32, device=d)
    outs = [wp.empty(E * T * C, dtype=t, device=d) for t in (wp.float64, wp.float64, wp.int32, wp.float64, wp.float64)]
    noise = wp.array(np.ascontiguousarray(noise_v, np.float64).reshape(-1), dtype=wp.float64, device=d)
    f64 = wp.float64
    wp.launch(
        readout_kernel,
        dim=E * C,
        inputs=[
            g, noise, T, C, ns, vec_sos(*sos), vec_zi(*zi), f64(ep.excitation_v), f64(ep.bridge_resistance_ohm),
            f64(ep.amp_gain), f64(ep.amp_offset_v), f64(ep.lsb_v), f64(ep.code_min), f64(ep.code_max),
            filt, primed, *outs,
        ],
        device=d,
    )
    names = ["resistance", "bridge_v", "adc", "filtered_v", "resistance_measured"]
    result = {n: o.numpy().reshape(E, T, C) for n, o in zip(names, outs) if keep is None or n in keep}
    return result, ElectronicsState(filt.numpy(), primed.numpy())

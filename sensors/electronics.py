"""Readout electronics: taxel columns in parallel -> Wheatstone bridge -> in-amp -> ADC -> digital Butterworth.

Source: cnt_pdms sect. 2.2 (bridge + in-amp, 14-bit NI USB-6009 at 100 Hz, 4th-order 10 Hz Butterworth);
bridge in exact form V = V_ex (R_s / (R_s + R_b) - 1/2) (Horowitz & Hill, The Art of Electronics, 3rd ed.).
Numpy reference and Warp kernels side by side; the electronics run in float64 on both so ADC codes agree.
Readout noise (white + 1/f) is drawn per step inside the readout kernel from the episode seeds, by a
counter-based RNG that its numpy mirror `readout_noise_batch` reproduces (construction below).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from sensors.cnt_pdms.params import ElectronicsParams
from sensors.warp_setup import to_host_many

MAX_SECTIONS = 4  # 8th-order filter at most (ElectronicsConfig.filter_order <= 8)
vec_sos = wp.types.vector(length=6 * MAX_SECTIONS, dtype=wp.float64)
vec_zi = wp.types.vector(length=2 * MAX_SECTIONS, dtype=wp.float64)


@dataclass
class ElectronicsState:
    """Per (episode, channel): Butterworth state [B, 2*MAX_SECTIONS] and pink-filter state [B, PINK_STATES]
    (float64), and whether the first sample was seen (filter primed at it, pink state drawn) [B] int32."""

    filt: np.ndarray
    primed: np.ndarray
    pink: np.ndarray

    @classmethod
    def zeros(cls, n: int) -> "ElectronicsState":
        return cls(np.zeros((n, 2 * MAX_SECTIONS)), np.zeros(n, np.int32), np.zeros((n, PINK_STATES)))


@dataclass(frozen=True)
class NoiseSeeds:
    """Readout noise drawn inside the readout kernel from the episodes' seeds (uint64 as Python ints, one per
    episode) instead of an uploaded [E,T,C] array; the same values as `readout_noise_batch(seeds, ...)`."""

    seeds: list[int]
    white_v: float  # rms of the white component (V)
    pink_v: float  # rms of the 1/f component (V)


# ----------------------------------------------------------------------------------------- readout noise
#
# Counter-based normals, computed the same way in numpy and in the Warp kernel (uint64 wraps modulo 2^64):
#   mix(z)           splitmix64 finalizer: z ^= z >> 30; z *= M1; z ^= z >> 27; z *= M2; z ^= z >> 31
#   key(seed, c, j)  mix(seed ^ mix(N_STREAMS * c + j + 1)), channel c, stream j (white, pink drive, pink init)
#   u(key, n)        ((mix(key + GAMMA * (n + 1)) >> 11) + 1) * 2^-53 in (0, 1]: the top 53 bits of output n
#                    of SplitMix64 seeded with key (Steele, Lea & Flood, OOPSLA 2014)
#   z(key, k)        sqrt(-2 ln u(key, 2k)) * cos(2 pi u(key, 2k + 1)), Box-Muller in float64
# Step k (absolute, from the episode's start) uses normal k of the white and of the pink-drive stream; the
# pink filter's initial state uses normals 0..6 of the init stream.

MIX_M1, MIX_M2, GAMMA = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB, 0x9E3779B97F4A7C15
N_STREAMS = 3
STREAM_WHITE, STREAM_PINK, STREAM_INIT = 0, 1, 2
UNIT_53, TWO_PI = 2.0**-53, 2.0 * np.pi

# Pink (1/f) noise: Kellet's refined filter, a bank of first-order sections driven by one white input
# (music-dsp 1999; sums of first-order filters as 1/f approximations: Kasdin, Proc. IEEE 83(5), 1995),
# +-0.05 dB of 1/f over ~9 octaves above fs/4800. Per step: b_i = A_i b_i + C_i w (i < 6);
# pink = b_0 + ... + b_5 + b_6 + E w; then b_6 = D w.
PINK_A = np.array([0.99886, 0.99332, 0.96900, 0.86650, 0.55000, -0.7616])
PINK_C = np.array([0.0555179, 0.0750759, 0.1538520, 0.3104856, 0.5329522, -0.0168980])
PINK_D, PINK_E = 0.115926, 0.5362
PINK_STATES = 7  # b_0 .. b_6


def _pink_stationary() -> tuple[np.ndarray, float]:
    """Stationary covariance of the state (b_0..b_6) under unit white input -> (its Cholesky factor, std of pink)."""
    p = np.empty((PINK_STATES, PINK_STATES))
    p[:6, :6] = np.outer(PINK_C, PINK_C) / (1.0 - np.outer(PINK_A, PINK_A))
    p[:6, 6] = p[6, :6] = PINK_C * PINK_D
    p[6, 6] = PINK_D**2
    g = np.append(PINK_A, 1.0)  # pink = g . (state before the step) + (sum C + E) w
    return np.linalg.cholesky(p), float(np.sqrt(g @ p @ g + (PINK_C.sum() + PINK_E) ** 2))


PINK_CHOL, PINK_STD = _pink_stationary()


def _mix(z: np.ndarray) -> np.ndarray:
    """splitmix64 finalizer, in place on a uint64 array (wraps modulo 2^64)."""
    z ^= z >> np.uint64(30)
    z *= np.uint64(MIX_M1)
    z ^= z >> np.uint64(27)
    z *= np.uint64(MIX_M2)
    z ^= z >> np.uint64(31)
    return z


def _uniform(key: np.ndarray, n: np.ndarray) -> np.ndarray:
    """u(key, n) for keys [R, 1] and counters n [K] (uint64) -> [R, K] float64 in (0, 1]."""
    h = _mix(key + np.uint64(GAMMA) * (n + np.uint64(1)))
    h >>= np.uint64(11)
    h += np.uint64(1)
    return h * UNIT_53


def _normals(key: np.ndarray, k: np.ndarray) -> np.ndarray:
    """z(key, k) for keys [R, 1] and steps k [K] (uint64) -> [R, K] float64."""
    r = np.log(_uniform(key, np.uint64(2) * k))
    r *= -2.0
    np.sqrt(r, out=r)
    c = _uniform(key, np.uint64(2) * k + np.uint64(1))
    c *= TWO_PI
    np.cos(c, out=c)
    r *= c
    return r


def readout_noise_batch(seeds: list[int], n_steps: int, n_channels: int, white_v: float, pink_v: float) -> np.ndarray:
    """Noise at the ADC input, [E, T, C] float64: white + 1/f per (episode, channel) from the episode's seed.
    The numpy mirror of what `readout_warp` adds with `NoiseSeeds` (construction above): the pink filter starts
    in its stationary state (PINK_CHOL times 7 normals of the init stream) and is scaled by pink_v / PINK_STD.
    Runs in blocks of (episode, channel) rows small enough to stay in cache."""
    from scipy.signal import lfilter  # here, not at the top: scipy.signal costs ~1 s of import that the GPU feed never needs

    seed = np.repeat(np.asarray(seeds, dtype=np.uint64), n_channels)[:, None]  # one row per (episode, channel)
    chan = np.tile(np.arange(n_channels, dtype=np.uint64), len(seeds))[:, None]
    steps = np.arange(n_steps, dtype=np.uint64)
    out = np.empty((len(seed), n_steps))
    rows = max(1, 32768 // max(n_steps, 1))
    with np.errstate(over="ignore"):
        keys = [_mix(seed ^ _mix(np.uint64(N_STREAMS) * chan + np.uint64(j + 1))) for j in range(N_STREAMS)]
        for r0 in range(0, len(seed), rows):
            kw, kp, ki = (k[r0 : r0 + rows] for k in keys)
            w = _normals(kp, steps)  # pink drive [R, T]
            z = _normals(ki, np.arange(PINK_STATES, dtype=np.uint64))
            b = sum(z[:, j, None] * PINK_CHOL[:, j] for j in range(PINK_STATES))  # initial state [R, 7], L z
            pink = lfilter([PINK_C[0]], [1.0, -PINK_A[0]], w, zi=PINK_A[0] * b[:, :1])[0]
            for i in range(1, 6):  # y[k] = A y[k-1] + C w[k] per section, summed in the kernel's order
                pink += lfilter([PINK_C[i]], [1.0, -PINK_A[i]], w, zi=PINK_A[i] * b[:, i : i + 1])[0]
            pink[:, 0] += b[:, 6]
            pink[:, 1:] += w[:, :-1] * PINK_D
            pink += w * PINK_E
            pink *= pink_v / PINK_STD
            white = _normals(kw, steps)
            white *= white_v
            np.add(white, pink, out=out[r0 : r0 + rows])
    return np.ascontiguousarray(out.reshape(len(seeds), n_channels, n_steps).transpose(0, 2, 1))


def readout_noise_v(seed: int, n_steps: int, n_channels: int, white_v: float, pink_v: float) -> np.ndarray:
    """Noise at the ADC input for one episode, [T, C] float64 (`readout_noise_batch` of one seed)."""
    return readout_noise_batch([seed], n_steps, n_channels, white_v, pink_v)[0]


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
    return out, ElectronicsState(z.reshape(E * C, -1), primed.reshape(-1), st.pink.copy())


def zero_phase(out: dict, ep) -> dict:
    """Offline zero-phase filtering of a recorded episode (ep.filter_mode == "zero_phase"): the Butterworth run
    forward and backward over each episode's ADC voltage (scipy.signal.sosfiltfilt, odd padding), so the
    recorded output has no phase lag (cnt_pdms sect. 2.2). `out` holds "filtered_v" = the unfiltered ADC
    voltage [E,T,C] from the readout; returns it with "filtered_v" and "resistance_measured" replaced.
    Runs on the host after either backend, so numpy and Warp stay equal."""
    from scipy.signal import sosfiltfilt

    if ep.offline_sos is None or "filtered_v" not in out:
        return out
    v = np.asarray(out["filtered_v"], np.float64)
    T = v.shape[1]
    pad = min(3 * (2 * ep.offline_sos.shape[0] + 1), T - 1)
    y = sosfiltfilt(ep.offline_sos, v, axis=1, padlen=max(pad, 0)) if T > 1 else v
    ratio = (y - ep.amp_offset_v) / ep.amp_gain / ep.excitation_v + 0.5
    return {**out, "filtered_v": y, "resistance_measured": ep.bridge_resistance_ohm * ratio / (1.0 - ratio)}


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


vec_pink = wp.types.vector(length=PINK_STATES, dtype=wp.float64)
vec_pink_ar = wp.types.vector(length=6, dtype=wp.float64)
mat_pink = wp.types.matrix(shape=(PINK_STATES, PINK_STATES), dtype=wp.float64)
_M1, _M2, _GAMMA = (wp.constant(wp.uint64(v)) for v in (MIX_M1, MIX_M2, GAMMA))


@wp.func
def _mix_wp(z: wp.uint64) -> wp.uint64:
    z = (z ^ (z >> wp.uint64(30))) * _M1
    z = (z ^ (z >> wp.uint64(27))) * _M2
    return z ^ (z >> wp.uint64(31))


@wp.func
def _stream_key_wp(seed: wp.uint64, c: int, j: int) -> wp.uint64:
    return _mix_wp(seed ^ _mix_wp(wp.uint64(N_STREAMS) * wp.uint64(c) + wp.uint64(j + 1)))


@wp.func
def _normal_wp(key: wp.uint64, k: int) -> wp.float64:
    n1 = wp.uint64(2) * wp.uint64(k) + wp.uint64(1)
    u1 = wp.float64((_mix_wp(key + _GAMMA * n1) >> wp.uint64(11)) + wp.uint64(1)) * wp.float64(UNIT_53)
    u2 = wp.float64((_mix_wp(key + _GAMMA * (n1 + wp.uint64(1))) >> wp.uint64(11)) + wp.uint64(1)) * wp.float64(UNIT_53)
    return wp.sqrt(wp.float64(-2.0) * wp.log(u1)) * wp.cos(wp.float64(TWO_PI) * u2)


@wp.func
def _noise_v_wp(key_white: wp.uint64, key_pink: wp.uint64, k: int, b: vec_pink, white_v: wp.float64,
                pink_scale: wp.float64, pink_a: vec_pink_ar, pink_c: vec_pink_ar, pink_d: wp.float64,
                pink_e: wp.float64):
    """One sample of readout noise (V) at absolute step k: the pink AR bank advanced by one step plus white;
    returns (the advanced pink state, the noise). Shared by the serial and the chunked readout kernels."""
    w = _normal_wp(key_pink, k)
    for i in range(6):
        b[i] = pink_a[i] * b[i] + w * pink_c[i]
    pink = b[0] + b[1] + b[2] + b[3] + b[4] + b[5] + b[6] + w * pink_e
    b[6] = w * pink_d
    return b, white_v * _normal_wp(key_white, k) + pink_scale * pink


@wp.func
def _bridge_adc_wp(g: wp.float64, nv: wp.float64, v_ex: wp.float64, r_b: wp.float64, gain: wp.float64,
                   offset: wp.float64, lsb: wp.float64, code_min: wp.float64, code_max: wp.float64):
    """Conductance (S) -> (resistance ohm, bridge voltage V, ADC code, ADC voltage V) with noise nv (V) added
    before the converter."""
    r_s = wp.float64(1.0) / g
    vb = v_ex * (r_s / (r_s + r_b) - wp.float64(0.5))
    v = gain * vb + offset + nv
    code = wp.min(wp.max(wp.round(v / lsb), code_min), code_max)
    return r_s, vb, code, code * lsb


@wp.func
def _sos_wp(x: wp.float64, z: vec_zi, sos: vec_sos, n_sections: int):
    """One sample through the Butterworth cascade (transposed direct form II per section); returns (state, y)."""
    for i in range(MAX_SECTIONS):
        if i < n_sections:
            y = sos[6 * i + 0] * x + z[2 * i + 0]
            z[2 * i + 0] = sos[6 * i + 1] * x - sos[6 * i + 4] * y + z[2 * i + 1]
            z[2 * i + 1] = sos[6 * i + 2] * x - sos[6 * i + 5] * y
            x = y
    return z, x


@wp.func
def _measured_r_wp(x: wp.float64, offset: wp.float64, gain: wp.float64, v_ex: wp.float64, r_b: wp.float64) -> wp.float64:
    """The resistance the host computes back from the (filtered) ADC voltage, ohm."""
    ratio = (x - offset) / gain / v_ex + wp.float64(0.5)
    return r_b * ratio / (wp.float64(1.0) - ratio)


@wp.kernel
def readout_kernel(
    g: wp.array(dtype=wp.float64),  # [E*T*C]
    noise: wp.array(dtype=wp.float64),  # [E*T*C] explicit noise (V), read when seeded == 0
    seeded: int,  # 1: draw the noise here from seeds (see the construction above)
    seeds: wp.array(dtype=wp.uint64),  # [E]
    t0: int,  # absolute step of the first sample (counter offset)
    white_v: wp.float64,
    pink_scale: wp.float64,  # pink_v / PINK_STD
    pink_a: vec_pink_ar,
    pink_c: vec_pink_ar,
    pink_d: wp.float64,
    pink_e: wp.float64,
    pink_chol: mat_pink,
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
    st_pink: wp.array(dtype=vec_pink),
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
    b = st_pink[tid]
    key_white = wp.uint64(0)
    key_pink = wp.uint64(0)
    if seeded != 0:
        key_white = _stream_key_wp(seeds[ep], c, STREAM_WHITE)
        key_pink = _stream_key_wp(seeds[ep], c, STREAM_PINK)
        if primed == 0:  # episode start: the pink filter's state from its stationary distribution
            key_init = _stream_key_wp(seeds[ep], c, STREAM_INIT)
            n = vec_pink()
            for j in range(PINK_STATES):
                n[j] = _normal_wp(key_init, j)
            b = pink_chol * n
    for k in range(n_steps):
        idx = (ep * n_steps + k) * n_channels + c
        nv = wp.float64(0.0)
        if seeded != 0:
            b, nv = _noise_v_wp(key_white, key_pink, t0 + k, b, white_v, pink_scale, pink_a, pink_c, pink_d, pink_e)
        else:
            nv = noise[idx]
        r_s, vb, code, x = _bridge_adc_wp(g[idx], nv, v_ex, r_b, gain, offset, lsb, code_min, code_max)
        if primed == 0:
            for j in range(2 * MAX_SECTIONS):
                z[j] = zi_unit[j] * x
            primed = 1
        z, x = _sos_wp(x, z, sos, n_sections)
        out_r[idx] = r_s
        out_vb[idx] = vb
        out_code[idx] = int(code)
        out_vf[idx] = x
        out_rm[idx] = _measured_r_wp(x, offset, gain, v_ex, r_b)
    st_filt[tid] = z
    st_primed[tid] = primed
    st_pink[tid] = b


# ------------------------------------------------------------------- readout in parallel over time (CUDA)
#
# The serial readout_kernel above runs one thread per (episode, channel) through all T samples: with one
# channel per episode that is a few hundred threads on a GPU of ~10^5. The same readout split over time
# chunks of L samples, one thread per (episode, channel, chunk): the only recursions are the pink filter
# (six first-order sections, diagonal) and the Butterworth cascade. The pink filter's chunk start states come
# from a scan: pass 1 runs each chunk from a zero state, pass 2 carries b_start[j+1] = A^L b_start[j] + b_zero[j]
# per (episode, channel), pass 3 reruns each chunk from its start state and computes everything per sample.
# A pass-through filter (filter_mode zero_phase or off: sos = identity) needs nothing more; a causal
# Butterworth runs afterwards in one thread per (episode, channel) over the ADC voltages (readout_filter_kernel).
# Values equal the serial kernel's up to float64 rounding of the pink state (a code within rounding of an LSB
# boundary may land one count off, as between devices).

READOUT_THREADS = 65536  # (episode, channel, chunk) threads to aim for; chunks at least MIN_CHUNK samples
MIN_CHUNK = 8


@wp.kernel
def pink_chunk_kernel(
    seeds: wp.array(dtype=wp.uint64), t0: int, n_steps: int, n_channels: int, n_chunks: int, chunk: int,
    pink_a: vec_pink_ar, pink_c: vec_pink_ar, pink_d: wp.float64,
    b_zero: wp.array(dtype=vec_pink),  # [E*C*n_chunks] out: chunk-end state from a zero start (b_6 = D w_last)
):
    tid = wp.tid()
    row = tid // n_chunks
    j = tid - row * n_chunks
    ep = row // n_channels
    c = row - ep * n_channels
    key_pink = _stream_key_wp(seeds[ep], c, STREAM_PINK)
    b = vec_pink()
    k1 = wp.min(n_steps, (j + 1) * chunk)
    for k in range(j * chunk, k1):
        w = _normal_wp(key_pink, t0 + k)
        for i in range(6):
            b[i] = pink_a[i] * b[i] + w * pink_c[i]
        b[6] = w * pink_d
    b_zero[tid] = b


def _chunk_decay(chunk: int, n_steps: int, n_chunks: int) -> tuple[list[float], list[float]]:
    """PINK_A[i] ** steps for a whole chunk and for the last one, by repeated float64 multiplication in the order
    the carry kernel used to run it per chunk (IEEE products: the same bits), so the kernel's serial loop over
    the chunks does no power loops (0.27 of the H100 chain's 10.5 GPU-ms, transduction-h100-s12.json)."""
    def power(a: float, steps: int) -> float:
        a_l = 1.0
        for _ in range(steps):
            a_l = a_l * a
        return a_l

    last = min(n_steps, n_chunks * chunk) - (n_chunks - 1) * chunk
    return [power(float(a), chunk) for a in PINK_A], [power(float(a), last) for a in PINK_A]


@wp.kernel
def pink_carry_kernel(
    seeds: wp.array(dtype=wp.uint64), n_channels: int, n_chunks: int,
    decay_full: vec_pink_ar,  # PINK_A ** chunk (`_chunk_decay`)
    decay_last: vec_pink_ar,  # PINK_A ** (steps of the last chunk)
    pink_chol: mat_pink,
    b_zero: wp.array(dtype=vec_pink),
    st_primed: wp.array(dtype=wp.int32), st_pink: wp.array(dtype=vec_pink),
    b_start: wp.array(dtype=vec_pink),  # [E*C*n_chunks] out
):
    row = wp.tid()
    ep = row // n_channels
    c = row - ep * n_channels
    b = st_pink[row]
    if st_primed[row] == 0:  # episode start: the pink filter's state from its stationary distribution
        key_init = _stream_key_wp(seeds[ep], c, STREAM_INIT)
        n = vec_pink()
        for j in range(PINK_STATES):
            n[j] = _normal_wp(key_init, j)
        b = pink_chol * n
    for j in range(n_chunks):
        b_start[row * n_chunks + j] = b
        decay = decay_full
        if j == n_chunks - 1:
            decay = decay_last
        bz = b_zero[row * n_chunks + j]
        for i in range(6):
            b[i] = decay[i] * b[i] + bz[i]
        b[6] = bz[6]
    st_pink[row] = b


@wp.kernel
def readout_chunk_kernel(
    g: wp.array(dtype=wp.float64),  # [E*T*C]
    noise: wp.array(dtype=wp.float64),  # [E*T*C] explicit noise (V), read when seeded == 0
    seeded: int,
    seeds: wp.array(dtype=wp.uint64),
    t0: int,
    white_v: wp.float64,
    pink_scale: wp.float64,
    pink_a: vec_pink_ar,
    pink_c: vec_pink_ar,
    pink_d: wp.float64,
    pink_e: wp.float64,
    b_start: wp.array(dtype=vec_pink),  # [E*C*n_chunks]
    n_steps: int,
    n_channels: int,
    n_chunks: int,
    chunk: int,
    filtered: int,  # 0: pass-through filter, the ADC voltage is the output; 1: readout_filter_kernel follows
    v_ex: wp.float64,
    r_b: wp.float64,
    gain: wp.float64,
    offset: wp.float64,
    lsb: wp.float64,
    code_min: wp.float64,
    code_max: wp.float64,
    out_r: wp.array(dtype=wp.float64),
    out_vb: wp.array(dtype=wp.float64),
    out_code: wp.array(dtype=wp.int32),
    out_vf: wp.array(dtype=wp.float64),  # the ADC voltage (filtered later where filtered != 0)
    out_rm: wp.array(dtype=wp.float64),
):
    tid = wp.tid()  # (episode, channel, chunk)
    row = tid // n_chunks
    j = tid - row * n_chunks
    ep = row // n_channels
    c = row - ep * n_channels
    key_white = wp.uint64(0)
    key_pink = wp.uint64(0)
    b = vec_pink()
    if seeded != 0:
        key_white = _stream_key_wp(seeds[ep], c, STREAM_WHITE)
        key_pink = _stream_key_wp(seeds[ep], c, STREAM_PINK)
        b = b_start[tid]
    k1 = wp.min(n_steps, (j + 1) * chunk)
    for k in range(j * chunk, k1):
        idx = (ep * n_steps + k) * n_channels + c
        nv = wp.float64(0.0)
        if seeded != 0:
            b, nv = _noise_v_wp(key_white, key_pink, t0 + k, b, white_v, pink_scale, pink_a, pink_c, pink_d, pink_e)
        else:
            nv = noise[idx]
        r_s, vb, code, x = _bridge_adc_wp(g[idx], nv, v_ex, r_b, gain, offset, lsb, code_min, code_max)
        out_r[idx] = r_s
        out_vb[idx] = vb
        out_code[idx] = int(code)
        out_vf[idx] = x
        if filtered == 0:
            out_rm[idx] = _measured_r_wp(x, offset, gain, v_ex, r_b)


@wp.kernel
def readout_filter_kernel(
    n_steps: int, n_channels: int, n_sections: int, sos: vec_sos, zi_unit: vec_zi,
    v_ex: wp.float64, r_b: wp.float64, gain: wp.float64, offset: wp.float64,
    st_filt: wp.array(dtype=vec_zi), st_primed: wp.array(dtype=wp.int32),
    out_vf: wp.array(dtype=wp.float64),  # in: ADC voltage; out: filtered
    out_rm: wp.array(dtype=wp.float64),
):
    tid = wp.tid()  # (episode, channel): the Butterworth cascade of readout_kernel, over the ADC voltages
    ep = tid // n_channels
    c = tid - ep * n_channels
    z = st_filt[tid]
    primed = st_primed[tid]
    for k in range(n_steps):
        idx = (ep * n_steps + k) * n_channels + c
        x = out_vf[idx]
        if primed == 0:
            for j in range(2 * MAX_SECTIONS):
                z[j] = zi_unit[j] * x
            primed = 1
        z, x = _sos_wp(x, z, sos, n_sections)
        out_vf[idx] = x
        out_rm[idx] = _measured_r_wp(x, offset, gain, v_ex, r_b)
    st_filt[tid] = z
    st_primed[tid] = primed


def _pass_through(sos: np.ndarray, zi: np.ndarray, ns: int) -> bool:
    """The filter is the identity (one section b0 = a0 = 1, the rest 0, zero initial state): y = x exactly."""
    return ns == 1 and np.array_equal(sos[:6], [1.0, 0.0, 0.0, 1.0, 0.0, 0.0]) and not np.any(zi)


def _readout_chunked(g, E, T, C, noise_in, seeded, ep, sos, zi, ns, filt, primed, pink, outs, d, chunks=None):
    """Launch the time-parallel readout (passes above) into `outs`; state arrays updated in place."""
    f64 = wp.float64
    rows = E * C
    nc = chunks or max(1, min(-(-T // MIN_CHUNK), -(-READOUT_THREADS // max(rows, 1))))
    L = -(-T // nc) if T else 1
    nc = -(-T // L) if T else 1
    pa, pc = vec_pink_ar(*PINK_A), vec_pink_ar(*PINK_C)
    b_start = wp.empty(rows * nc if seeded else 0, dtype=vec_pink, device=d)
    if seeded and T > 0:
        b_zero = wp.empty(rows * nc, dtype=vec_pink, device=d)
        wp.launch(pink_chunk_kernel, dim=rows * nc, inputs=[noise_in[2], noise_in[3], T, C, nc, L, pa, pc, f64(PINK_D), b_zero], device=d)
        d_full, d_last = _chunk_decay(L, T, nc)
        wp.launch(pink_carry_kernel, dim=rows, inputs=[noise_in[2], C, nc, vec_pink_ar(*d_full), vec_pink_ar(*d_last),
                                                       mat_pink(*PINK_CHOL.ravel()), b_zero,
                                                       primed, pink, b_start], device=d)
    filtered = 0 if _pass_through(sos, zi, ns) else 1
    consts = [f64(ep.excitation_v), f64(ep.bridge_resistance_ohm), f64(ep.amp_gain), f64(ep.amp_offset_v)]
    wp.launch(
        readout_chunk_kernel, dim=rows * nc,
        inputs=[g, *noise_in, pa, pc, f64(PINK_D), f64(PINK_E), b_start, T, C, nc, L, filtered, *consts,
                f64(ep.lsb_v), f64(ep.code_min), f64(ep.code_max), *outs],
        device=d,
    )
    if filtered:
        wp.launch(readout_filter_kernel, dim=rows, inputs=[T, C, ns, vec_sos(*sos), vec_zi(*zi), *consts, filt, primed,
                                                           outs[3], outs[4]], device=d)
    elif T > 0:
        primed.fill_(1)


@wp.kernel
def taxel_channels_kernel(
    cond: wp.array(dtype=wp.float32),  # [E*T*N]
    stress: wp.array(dtype=wp.float32),  # [E*T*N]
    n_taxels: int,
    area: float,
    g_out: wp.array(dtype=wp.float64),  # [E*T*N]: channel n = taxel n
    force_out: wp.array(dtype=wp.float64),  # [E*T]
):
    # one bridge per taxel (sensor.readout = taxel): the channel conductance is the taxel's; one thread per
    # (episode, step) row sums the force in taxel order (the same order on every device)
    et = wp.tid()
    base = et * n_taxels
    f = wp.float64(0.0)
    for j in range(n_taxels):
        f += wp.float64(stress[base + j])
        g_out[base + j] = wp.float64(cond[base + j])
    force_out[et] = f * wp.float64(area)


@wp.kernel
def _codes_int16(src: wp.array(dtype=wp.int32), dst: wp.array(dtype=wp.int16)):
    i = wp.tid()
    dst[i] = wp.int16(src[i])


def sum_channels_warp(
    cond: wp.array, stress: wp.array, taxel_channel: np.ndarray, n_channels: int, area_m2: float,
    shape: tuple[int, int, int], device: str,
):
    """Flat [E*T*N] taxel conductance and stress on the device -> channel conductance [E*T*C] and force [E*T].
    One channel per taxel (C = N, channel n = taxel n) takes a plain per-row kernel instead of C tile
    reductions per row (bench_gpu_pipeline.py --parts chain times both)."""
    E, T, N = shape
    g = wp.empty(E * T * n_channels, dtype=wp.float64, device=device)
    force = wp.empty(E * T, dtype=wp.float64, device=device)
    if n_channels == N and np.array_equal(taxel_channel, np.arange(N)):
        wp.launch(taxel_channels_kernel, dim=E * T, inputs=[cond, stress, N, float(area_m2), g, force], device=device)
        return g, force
    tc = wp.array(np.asarray(taxel_channel, np.int32), dtype=wp.int32, device=device)
    wp.launch_tiled(
        sum_channels_kernel, dim=[E * T], inputs=[cond, stress, tc, N, n_channels, float(area_m2), g, force],
        block_dim=REDUCE_BLOCK if device.startswith("cuda") else 1, device=device,
    )
    return g, force


def readout_warp(
    g: wp.array, shape: tuple[int, int, int], noise: np.ndarray | NoiseSeeds, ep: ElectronicsParams,
    state: ElectronicsState | None, device: str, keep=None, t0: int = 0, adc_dtype=np.int32, parallel=None,
    return_state: bool = True,
):
    """Channel conductance on the device (flat [E*T*C]) -> (dict of numpy [E,T,C] outputs, state).
    noise: [E,T,C] noise at the ADC input (V, uploaded), or NoiseSeeds: drawn in the kernel, no host work;
    t0: absolute step of the first sample (with NoiseSeeds, run in time chunks by passing the returned state
    and t0 = samples done: the same noise as one call). keep: names of the outputs to copy back to the host
    (default all: resistance, bridge_v, adc, filtered_v, resistance_measured); adc_dtype=int16 narrows the
    codes on the device (an ADC of <= 16 bits), halving what crosses the bus. parallel: None = the time-parallel
    readout on CUDA and the serial kernel on the CPU (its bytes unchanged); True / False forces it; an int
    forces it with that many time chunks (tests). return_state=False: the state is not copied back (None), for a
    caller whose episodes end here."""
    E, T, C = shape
    d = device
    sos, zi, ns = _sos_vectors(ep)
    if state is None:  # episodes that start here: the zero state made on the device (no uploads to order)
        filt = wp.zeros(E * C, dtype=vec_zi, device=d)
        primed = wp.zeros(E * C, dtype=wp.int32, device=d)
        pink = wp.zeros(E * C, dtype=vec_pink, device=d)
    else:
        filt = wp.array(state.filt, dtype=vec_zi, device=d)
        primed = wp.array(state.primed, dtype=wp.int32, device=d)
        pink = wp.array(state.pink, dtype=vec_pink, device=d)
    outs = [wp.empty(E * T * C, dtype=t, device=d) for t in (wp.float64, wp.float64, wp.int32, wp.float64, wp.float64)]
    f64 = wp.float64
    if isinstance(noise, NoiseSeeds):
        if len(noise.seeds) != E:
            raise ValueError(f"need one seed per episode ({E}); got {len(noise.seeds)}")
        seeds = wp.array(np.asarray(noise.seeds, dtype=np.uint64), dtype=wp.uint64, device=d)
        noise_in = [wp.empty(0, dtype=wp.float64, device=d), 1, seeds, t0, f64(noise.white_v), f64(noise.pink_v / PINK_STD)]
    else:
        arr = wp.array(np.ascontiguousarray(noise, np.float64).reshape(-1), dtype=wp.float64, device=d)
        noise_in = [arr, 0, wp.empty(0, dtype=wp.uint64, device=d), t0, f64(0.0), f64(0.0)]
    if parallel is None:
        parallel = wp.get_device(d).is_cuda
    if parallel:
        _readout_chunked(g, E, T, C, noise_in, isinstance(noise, NoiseSeeds), ep, sos, zi, ns, filt, primed, pink, outs, d,
                         chunks=None if parallel is True else int(parallel))
    else:
        wp.launch(
            readout_kernel,
            dim=E * C,
            inputs=[
                g, *noise_in, vec_pink_ar(*PINK_A), vec_pink_ar(*PINK_C), f64(PINK_D), f64(PINK_E), mat_pink(*PINK_CHOL.ravel()),
                T, C, ns, vec_sos(*sos), vec_zi(*zi), f64(ep.excitation_v), f64(ep.bridge_resistance_ohm),
                f64(ep.amp_gain), f64(ep.amp_offset_v), f64(ep.lsb_v), f64(ep.code_min), f64(ep.code_max),
                filt, primed, pink, *outs,
            ],
            device=d,
        )
    names = ["resistance", "bridge_v", "adc", "filtered_v", "resistance_measured"]
    if np.dtype(adc_dtype) == np.int16:  # narrow the codes on the device: half the bytes to copy back
        codes = wp.empty(E * T * C, dtype=wp.int16, device=d)
        wp.launch(_codes_int16, dim=E * T * C, inputs=[outs[2], codes], device=d)
        outs[2] = codes
    picked = [(n, o) for n, o in zip(names, outs) if keep is None or n in keep]
    hosts = to_host_many([o for _, o in picked], [f"readout {n}" for n, _ in picked])
    result = {n: h.reshape(E, T, C) for (n, _), h in zip(picked, hosts)}
    if not return_state:
        return result, None
    return result, ElectronicsState(filt.numpy(), primed.numpy(), pink.numpy())

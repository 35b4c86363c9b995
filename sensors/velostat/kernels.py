"""Warp kernels of the `velostat` chain: the same equations as sensors/velostat/reference.py (tests compare them).

film kernels: one thread per (episode, taxel), the time loop inside the kernel with the creep state in
registers (aging: theta, a, p_prev; spectrum: the K terms) (TECH-NOTES: looping over time in one launch beats one launch per step); layout [E, T, N].
readout kernel: one thread per (episode, sample), a loop over the taxels (parallel contact paths),
then noise, clipping and ADC quantisation.
frame-sums kernel (GPU path, load field left on the device): one thread per (episode, sample), a loop over the
taxels: the float32 film input and the float64 force and contact centroid of `reference.force_centroid_numpy`.
"""

# no `from __future__ import annotations`: Warp must see the closure types as real objects

import functools

import numpy as np
import warp as wp

from sensors.velostat.reference import FilmParams, ReadoutParams, finish
from sensors.warp_setup import init_warp, resolve_device


@functools.cache
def film_kernel(n_creep: int):
    vec_k = wp.types.vector(length=n_creep, dtype=wp.float32)

    def film(
        pressure: wp.array(dtype=wp.float32),  # [E*T*N]
        n_steps: int,
        n_taxels: int,
        g_ref: wp.array(dtype=wp.float32),  # [N]
        drive: wp.array(dtype=wp.float32),  # [N]
        decay: vec_k,
        w1: vec_k,
        inv_pc: float,
        inv_pref: float,
        expo: float,
        state: wp.array(dtype=vec_k),  # [E*N] in/out
        out: wp.array(dtype=wp.float32),  # [E*T*N]
    ):
        tid = wp.tid()
        ep = tid // n_taxels
        n = tid - ep * n_taxels
        c = state[tid]
        gr = g_ref[n]
        dr = drive[n]
        base = ep * n_steps * n_taxels + n
        for k in range(n_steps):
            idx = base + k * n_taxels
            p = wp.max(pressure[idx], 0.0)
            phi = dr * wp.log(1.0 + p * inv_pc)
            c = wp.cw_mul(decay, c) + w1 * phi
            cs = float(0.0)
            for j in range(n_creep):
                cs += c[j]
            g = float(0.0)
            if p > 0.0:
                g = gr * wp.pow((p + cs) * inv_pref, expo)
            out[idx] = g
        state[tid] = c

    film.__name__ = film.__qualname__ = f"velostat_film_k{n_creep}"
    return wp.kernel(film, module="unique", enable_backward=False), vec_k


@wp.kernel(enable_backward=False)
def velostat_film_aging(
    pressure: wp.array(dtype=wp.float32),  # [E*T*N]
    n_steps: int,
    n_taxels: int,
    g_ref: wp.array(dtype=wp.float32),  # [N]
    drive: wp.array(dtype=wp.float32),  # [N]
    inv_pc: float,
    inv_pref: float,
    expo: float,
    dt: float,
    inv_dt: float,
    inv_dpc: float,
    thc: float,
    rec: float,
    state: wp.array(dtype=wp.vec3),  # [E*N] in/out: (theta s, a, p_prev Pa)
    out: wp.array(dtype=wp.float32),  # [E*T*N]
):
    tid = wp.tid()
    ep = tid // n_taxels
    n = tid - ep * n_taxels
    st = state[tid]
    th = st[0]
    a = st[1]
    pp = st[2]
    gr = g_ref[n]
    dr = drive[n]
    base = ep * n_steps * n_taxels + n
    for k in range(n_steps):
        idx = base + k * n_taxels
        p = wp.max(pressure[idx], 0.0)
        g = float(0.0)
        if p > 0.0:
            r = wp.max((p - pp) * inv_dt, 0.0) * inv_dpc
            th_ss = float(0.0)
            if r > 0.0:
                th_ss = 1.0 / r
            th_new = th_ss
            if pp > 0.0:
                if r > 0.0:
                    th_new = th_ss + (th - th_ss) * wp.exp(-r * dt)
                else:
                    th_new = th + dt
                if th_new > th:
                    a = a + wp.log((th_new + thc) / (th + thc))
            th = th_new
            c = dr * wp.log(1.0 + p * inv_pc) * a
            g = gr * wp.pow((p + c) * inv_pref, expo)
        else:
            a = a * rec
            th = 0.0
        out[idx] = g
        pp = p
    state[tid] = wp.vec3(th, a, pp)


@wp.kernel(enable_backward=False)
def velostat_readout(
    cond: wp.array(dtype=wp.float32),  # [E*T*N]
    noise: wp.array(dtype=wp.float32),  # [E*T*3]
    n_taxels: int,
    r_force: wp.array(dtype=wp.float32),  # [N]
    v_x: wp.array(dtype=wp.float32),
    r_x: wp.array(dtype=wp.float32),
    v_y: wp.array(dtype=wp.float32),
    r_y: wp.array(dtype=wp.float32),
    current: float,
    compliance: float,
    gin: float,
    lsb: float,
    full: int,
    range_v: float,
    out_r: wp.array(dtype=wp.float32),  # [E*T*2]: film, true total
    out_v: wp.array(dtype=wp.float32),  # [E*T*3]: true force, x, y voltages
    out_code: wp.array(dtype=wp.int32),  # [E*T*3]
    out_vadc: wp.array(dtype=wp.float32),  # [E*T*3]
):
    s = wp.tid()
    base = s * n_taxels
    g_f = float(0.0)
    g_film = float(0.0)
    gx = float(0.0)
    sx = float(0.0)
    gy = float(0.0)
    sy = float(0.0)
    for n in range(n_taxels):
        g = cond[base + n]
        if g > 0.0:
            g_film += g
            g_f += 1.0 / (1.0 / g + r_force[n])
            a = 1.0 / (1.0 / g + r_x[n])
            gx += a
            sx += a * v_x[n]
            b = 1.0 / (1.0 / g + r_y[n])
            gy += b
            sy += b * v_y[n]
    r_true = float(1.0e12)
    if g_f > 0.0:
        r_true = 1.0 / g_f
    r_film = float(1.0e12)
    if g_film > 0.0:
        r_film = 1.0 / g_film
    vf = wp.min(current * r_true, compliance)
    vx = sx / (gx + gin)
    vy = sy / (gy + gin)
    out_r[2 * s] = r_film
    out_r[2 * s + 1] = r_true
    out_v[3 * s] = vf
    out_v[3 * s + 1] = vx
    out_v[3 * s + 2] = vy
    for c in range(3):
        v = out_v[3 * s + c] + noise[3 * s + c]
        v = wp.clamp(v, 0.0, range_v)
        code = wp.min(int(wp.floor(v / lsb)), full - 1)
        out_code[3 * s + c] = code
        out_vadc[3 * s + c] = (float(code) + 0.5) * lsb


@wp.kernel(enable_backward=False)
def velostat_frame_sums(
    pressure: wp.array2d(dtype=wp.float64),  # [E*T, N] (Pa), the load field on the device
    x: wp.array(dtype=wp.float64),  # [N] taxel centres (m)
    y: wp.array(dtype=wp.float64),
    area: wp.float64,  # taxel cell area (m^2)
    p32: wp.array(dtype=wp.float32),  # [E*T*N] out: the film's input, float32(pressure) (numpy's astype)
    sums: wp.array2d(dtype=wp.float64),  # [E*T, 3] out: force (N), centroid x, y (m; NaN unloaded)
    size_x: wp.float64,  # pad size (m), for the calibration unit under the centroid
    size_y: wp.float64,
    units_x: int,  # calibration units along x, y
    units_y: int,
    unit: wp.array(dtype=wp.int16),  # [E*T] out: unit index iy * units_x + ix under the centroid (-1 unloaded)
):
    f = wp.tid()
    n_taxels = pressure.shape[1]
    base = f * n_taxels
    s = wp.float64(0.0)
    sx = wp.float64(0.0)
    sy = wp.float64(0.0)
    for n in range(n_taxels):
        v = pressure[f, n]
        p32[base + n] = wp.float32(v)
        p = wp.max(v, wp.float64(0.0))
        s += p
        sx += p * x[n]
        sy += p * y[n]
    fz = s * area
    sums[f, 0] = fz
    if fz > wp.float64(0.0):
        cx = sx * area / fz
        cy = sy * area / fz
        sums[f, 1] = cx
        sums[f, 2] = cy
        # VelostatSensor.unit_of's float64 arithmetic, in its order (truncation toward zero, then clipped)
        ix = wp.clamp(int((cx / size_x + wp.float64(0.5)) * wp.float64(units_x)), 0, units_x - 1)
        iy = wp.clamp(int((cy / size_y + wp.float64(0.5)) * wp.float64(units_y)), 0, units_y - 1)
        unit[f] = wp.int16(iy * units_x + ix)
    else:
        nan = wp.float64(wp.nan)
        sums[f, 1] = nan
        sums[f, 2] = nan
        unit[f] = wp.int16(-1)


def frame_sums_device(pressure: wp.array, xy: np.ndarray, area: float, p32: wp.array | None = None, *,
                      units: tuple[float, float, int, int]):
    """A float64 load field on the device, flat (E T, N) -> (float32 film input [E*T*N], [E*T, 3] float64
    force and contact centroid, [E*T] int16 calibration unit under the centroid), all on its device
    (`velostat_frame_sums`). units: (pad size x, y (m), units along x, y) of the unit grid."""
    dev = pressure.device
    F, N = pressure.shape
    p32 = wp.empty(F * N, dtype=wp.float32, device=dev) if p32 is None else p32
    sums = wp.empty((F, 3), dtype=wp.float64, device=dev)
    unit = wp.empty(F, dtype=wp.int16, device=dev)
    xs = wp.array(np.ascontiguousarray(xy[:, 0], np.float64), dtype=wp.float64, device=dev)
    ys = wp.array(np.ascontiguousarray(xy[:, 1], np.float64), dtype=wp.float64, device=dev)
    sx, sy, ux, uy = units
    wp.launch(velostat_frame_sums, dim=F, inputs=[pressure, xs, ys, wp.float64(area), p32, sums, wp.float64(sx),
                                                  wp.float64(sy), int(ux), int(uy), unit], device=dev)
    return p32, sums, unit


def run_film_warp(pressure: np.ndarray, p: FilmParams, device: str = "cpu", state: np.ndarray | None = None):
    """pressure [E, T, N] -> conductance [E, T, N] float32, final state [E*N, K]."""
    init_warp()
    device = resolve_device(device)
    E, T, N = pressure.shape
    pr = wp.array(np.ascontiguousarray(pressure, np.float32).reshape(-1), dtype=wp.float32, device=device)
    out, st_d = run_film_device(pr, (E, T, N), p, device, state)
    return out.numpy().reshape(E, T, N), st_d.numpy()


def run_film_device(pr: wp.array, shape: tuple[int, int, int], p: FilmParams, device: str,
                    state: np.ndarray | None = None, out: wp.array | None = None):
    """float32 pressure [E*T*N] on `device` -> (conductance [E*T*N], final state [E*N]) on the device."""
    E, T, N = shape
    out = wp.empty(E * T * N, dtype=wp.float32, device=device) if out is None else out
    if p.model == "aging":
        return _run_aging_warp(pr, shape, p, device, state, out)
    kern, vec_k = film_kernel(p.n_creep)
    st = np.zeros((E * N, p.n_creep), np.float32) if state is None else np.asarray(state, np.float32)
    st_d = wp.array(st, dtype=vec_k, device=device)
    w1 = ((1.0 - p.decay) * p.weight).astype(np.float32)
    wp.launch(
        kern, dim=E * N, device=device,
        inputs=[pr, T, N, wp.array(p.g_ref_s.astype(np.float32), dtype=wp.float32, device=device),
                wp.array(p.creep_drive.astype(np.float32), dtype=wp.float32, device=device),
                vec_k(*p.decay.astype(np.float32)), vec_k(*w1), float(1.0 / p.p_c_pa), float(1.0 / p.p_ref_pa),
                float(p.exponent), st_d, out],
    )
    return out, st_d


def _run_aging_warp(pr: wp.array, shape: tuple[int, int, int], p: FilmParams, device, state: np.ndarray | None, out: wp.array):
    E, T, N = shape
    st = np.zeros((E * N, 3), np.float32) if state is None else np.asarray(state, np.float32)
    st_d = wp.array(st, dtype=wp.vec3, device=device)
    wp.launch(
        velostat_film_aging, dim=E * N, device=device,
        inputs=[pr, T, N, wp.array(p.g_ref_s.astype(np.float32), dtype=wp.float32, device=device),
                wp.array(p.creep_drive.astype(np.float32), dtype=wp.float32, device=device),
                float(1.0 / p.p_c_pa), float(1.0 / p.p_ref_pa), float(p.exponent), float(np.float32(p.dt_s)),
                float(np.float32(1.0 / p.dt_s)), float(1.0 / p.renewal_pa), float(p.cutoff_s),
                float(p.recovery_decay), st_d, out],
    )
    return out, st_d


def run_readout_warp(cond: np.ndarray, noise_v: np.ndarray, r: ReadoutParams, device: str = "cpu") -> dict[str, np.ndarray]:
    init_warp()
    device = resolve_device(device)
    E, T, N = cond.shape
    c = wp.array(np.ascontiguousarray(cond, np.float32).reshape(-1), dtype=wp.float32, device=device)
    return run_readout_device(c, (E, T, N), noise_v, r, device)


def run_readout_device(cond: wp.array, shape: tuple[int, int, int], noise_v: np.ndarray, r: ReadoutParams,
                       device: str) -> dict[str, np.ndarray]:
    """Conductance [E*T*N] float32 on `device`, noise [E, T, 3] (V) -> the decoded outputs (`finish`); only the
    (E, T, <= 3) outputs come back to the host (through page-locked buffers inside `host_staging`)."""
    from sensors.warp_setup import scratch, to_host

    E, T, N = shape

    def arr(a, dtype=wp.float32):
        return wp.array(np.ascontiguousarray(a, np.float32).reshape(-1), dtype=dtype, device=device)

    S = E * T
    out_r = scratch("velostat r", 2 * S, wp.float32, device)
    out_v = scratch("velostat v", 3 * S, wp.float32, device)
    out_c = scratch("velostat code", 3 * S, wp.int32, device)
    out_a = scratch("velostat vadc", 3 * S, wp.float32, device)
    full = 2**r.adc_bits
    wp.launch(
        velostat_readout, dim=S, device=device,
        inputs=[cond, arr(noise_v), N, arr(r.r_force_ohm), arr(r.v_x), arr(r.r_x_ohm), arr(r.v_y), arr(r.r_y_ohm),
                float(r.current_a), float(r.compliance_v), float(1.0 / r.input_resistance_ohm),
                float(np.float32(r.adc_range_v / full)), int(full), float(r.adc_range_v), out_r, out_v, out_c, out_a],
    )
    rr = to_host(out_r, "velostat r").reshape(E, T, 2)
    return finish(rr[..., 0], rr[..., 1], to_host(out_v, "velostat v").reshape(E, T, 3),
                  to_host(out_c, "velostat code").reshape(E, T, 3), to_host(out_a, "velostat vadc").reshape(E, T, 3), r)

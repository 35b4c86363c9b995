"""Warp kernels of the per-taxel CNT-PDMS chain (same equations as sensors/cnt_pdms/reference.py, which tests compare).

One thread per (episode, taxel) loops over time with the whole state in registers (TECH-NOTES: one
launch with the time loop inside beats one launch per step by ~7x on the GPU). Kernels are built per
(Prony terms, play operators) pair, so the term loops unroll at compile time. Memory layout [E, T, N]:
neighbouring threads read neighbouring taxels, so loads coalesce on CUDA.

The kernel writes strain, stress and conductance per taxel; the channel sums run afterwards as a tiled,
coalesced reduction (sensors/electronics.py). A variant that reduced over each thread block at every
step inside this kernel was measured slower on an H100 (3.6e10 vs 5.0e10 taxel-steps/s for the whole
chain): the per-step block synchronisation costs more than re-reading the arrays once. Two more fused variants
were measured slower on the H100 in session 6 (256 x 4096 x 1000, bench/results/logs/transduction-h100-s6-*):
tile sums per step in blocks of 32-256 taxels (33-36 ms against 13.0 ms for this kernel + the tiled sum), and
4-16 taxels per thread with per-thread partial sums, no sync (36-40 ms): both lose the memory parallelism.
Session 7 (`taxel_sum_kernel`, CUDA's pad path): one taxel per thread as here, warp shuffles instead of block
sums, partials stored 32 steps at a time: 10.1 ms for kernel + row sums against 13.0 ms for this kernel + the
tiled sum, with the outputs in kept buffers (bench/README.md, session 7).
"""

# no `from __future__ import annotations`: Warp must see the closure types as real objects

import functools

import numpy as np
import warp as wp

from sensors.cnt_pdms.params import TaxelParams
from sensors.cnt_pdms.reference import MAX_STRAIN_FRACTION, TaxelState
from sensors.percolation import (
    NetworkWp, conductance_ratio_approx_wp, conductance_ratio_wp, damage_approx_wp, damage_wp, fast_div, kinetics_wp,
    network_struct,
)
from sensors.warp_setup import init_warp, resolve_device

# The taxel step's float32 divisions and exp as CUDA's approximate instructions (__fdividef: 2 ulp, fast_div;
# sensors/percolation.py: fast_exp) instead of the IEEE-rounded ones (~10 instructions each, a slow path for the division): the fused
# kernel is bound by its arithmetic, not its loads and stores (bench/results/transduction-h100-s12.json: 9.64 ms
# with nothing per taxel written against 9.7-10.1 ms with both stores). CPU kernels are unchanged bit for bit (both
# fall back to the exact operations there); CUDA against the CPU stays within tests/test_gpu.py's rtol 1e-5.
APPROX_MATH = True


@functools.cache
def _taxel_types(n_prony: int, n_play: int):
    """The state vectors, the parameter struct and the step's invariants for this many Prony terms and play
    operators: one set, shared by the exact and the approximate kernels (so one Params value launches both)."""
    vec_p = wp.types.vector(length=n_prony, dtype=wp.float32)
    vec_k = wp.types.vector(length=n_play, dtype=wp.float32)
    strain_frac = float(MAX_STRAIN_FRACTION)

    @wp.struct
    class Params:
        prony_decay: vec_p
        prony_eb: vec_p  # E_i b_i
        play_r: vec_k
        play_w: vec_k
        e_inf: float
        e_lock: float
        recovery: float
        softening: float
        g0: float
        net: NetworkWp

    def invariants(p: Params):
        # the step's constants (the same float32 operations as before; the fused kernel hoists them out of its loop)
        e_max = strain_frac * p.e_lock
        eb_sum = float(0.0)
        w_sum = float(0.0)
        for i in range(n_prony):
            eb_sum += p.prony_eb[i]
        for j in range(n_play):
            w_sum += p.play_w[j]
        phi_max = e_max / (1.0 - e_max / p.e_lock)
        return e_max, eb_sum, w_sum, phi_max

    invariants.__name__ = invariants.__qualname__ = f"taxel_invariants_p{n_prony}_k{n_play}"
    return vec_p, vec_k, Params, wp.func(invariants)


@functools.cache
def taxel_kernels(n_prony: int, n_play: int, approx: bool = APPROX_MATH):
    """Kernels and types for this many Prony terms and play operators; compiled once per pair. approx: the step's
    divisions and exp as CUDA's approximate instructions (`APPROX_MATH`; the CPU's code is the same either way)."""
    vec_p, vec_k, Params, invariants_f = _taxel_types(n_prony, n_play)

    def core(p: Params, e_max: float, eb_sum: float, w_sum: float, phi_max: float, mode: int, d: float, e: float,
             phi: float, h: vec_p, s: float, z: vec_k, dmg: float):
        e_new = float(0.0)
        phi_new = float(0.0)
        m = 1.0 - p.softening * dmg
        if wp.static(approx):
            if mode == 1:
                phi_new = wp.clamp(fast_div(fast_div(d, m) - wp.dot(p.prony_decay, h) + eb_sum * phi,
                                                 p.e_inf + eb_sum), 0.0, phi_max)
                e_new = fast_div(phi_new, 1.0 + fast_div(phi_new, p.e_lock))
            else:
                e_new = wp.clamp(d, 0.0, e_max)
                phi_new = fast_div(e_new, 1.0 - fast_div(e_new, p.e_lock))
        else:
            if mode == 1:
                phi_new = wp.clamp((d / m - wp.dot(p.prony_decay, h) + eb_sum * phi) / (p.e_inf + eb_sum), 0.0, phi_max)
                e_new = phi_new / (1.0 + phi_new / p.e_lock)
            else:
                e_new = wp.clamp(d, 0.0, e_max)
                phi_new = e_new / (1.0 - e_new / p.e_lock)
        h_new = wp.cw_mul(p.prony_decay, h) + p.prony_eb * (phi_new - phi)
        sig = p.e_inf * phi_new
        for i in range(n_prony):
            sig += h_new[i]
        sig = m * sig
        s_new = kinetics_wp(p.net, s, e, e_new)
        dmg_new = float(0.0)
        if wp.static(approx):
            dmg_new = damage_approx_wp(p.net, dmg, e_new)
        else:
            dmg_new = damage_wp(p.net, dmg, e_new)
        e_net = (1.0 - w_sum) * s_new
        z_new = z
        for j in range(n_play):
            zj = wp.max(s_new - p.play_r[j], wp.min(s_new + p.play_r[j], z[j]))
            zj = s_new + (zj - s_new) * p.recovery
            z_new[j] = zj
            e_net += p.play_w[j] * zj
        g = float(0.0)
        if wp.static(approx):
            g = p.g0 * conductance_ratio_approx_wp(p.net, e_net, dmg_new)
        else:
            g = p.g0 * conductance_ratio_wp(p.net, e_net, dmg_new)
        return e_new, phi_new, h_new, s_new, z_new, dmg_new, sig, g

    core.__name__ = core.__qualname__ = f"taxel_core_p{n_prony}_k{n_play}_a{int(approx)}"
    core_f = wp.func(core)

    def step(p: Params, mode: int, d: float, e: float, phi: float, h: vec_p, s: float, z: vec_k, dmg: float):
        e_max, eb_sum, w_sum, phi_max = invariants_f(p)
        return core_f(p, e_max, eb_sum, w_sum, phi_max, mode, d, e, phi, h, s, z, dmg)

    step.__name__ = step.__qualname__ = f"taxel_step_p{n_prony}_k{n_play}_a{int(approx)}"
    step_f = wp.func(step)

    def chain(
        drive: wp.array(dtype=wp.float32),  # [E*T*N]
        n_steps: int,
        n_taxels: int,
        mode: int,
        p: Params,
        st_strain: wp.array(dtype=wp.float32),  # [E*N] in/out
        st_phi: wp.array(dtype=wp.float32),
        st_prony: wp.array(dtype=vec_p),
        st_gap: wp.array(dtype=wp.float32),
        st_play: wp.array(dtype=vec_k),
        st_damage: wp.array(dtype=wp.float32),
        out_strain: wp.array(dtype=wp.float32),  # [E*T*N]
        out_stress: wp.array(dtype=wp.float32),
        out_cond: wp.array(dtype=wp.float32),
    ):
        tid = wp.tid()
        ep = tid // n_taxels
        n = tid - ep * n_taxels
        e = st_strain[tid]
        phi = st_phi[tid]
        h = st_prony[tid]
        s = st_gap[tid]
        z = st_play[tid]
        dmg = st_damage[tid]
        base = ep * n_steps * n_taxels + n
        for k in range(n_steps):
            idx = base + k * n_taxels
            e, phi, h, s, z, dmg, sig, g = step_f(p, mode, drive[idx], e, phi, h, s, z, dmg)
            out_strain[idx] = e
            out_stress[idx] = sig
            out_cond[idx] = g
        st_strain[tid] = e
        st_phi[tid] = phi
        st_prony[tid] = h
        st_gap[tid] = s
        st_play[tid] = z
        st_damage[tid] = dmg

    chain.__name__ = chain.__qualname__ = f"taxel_chain_p{n_prony}_k{n_play}_a{int(approx)}"
    k_chain = wp.kernel(chain, module="unique", enable_backward=False)
    return {"chain": k_chain, "Params": Params, "vec_p": vec_p, "vec_k": vec_k, "invariants": invariants_f, "core": core_f}


# Sum over the 32 lanes of a CUDA warp of float32 values in float64, every lane getting the same sum (butterfly:
# xor-shuffles by 16, 8, 4, 2, 1; the first level shuffles the float32 and adds in float64, the same bits as
# converting first; a + b == b + a in IEEE arithmetic, so all lanes hold the same bits, in a fixed tree order):
# no shared memory and no block barrier, so the taxel loop keeps its memory parallelism. On the CPU a "group"
# is one thread and the sum is the value itself.
WARP_LANES = 32
_group_sum_snippet = """
#if defined(__CUDA_ARCH__)
    double v = (double)x + (double)__shfl_xor_sync(0xffffffffu, x, 16);
    v += __shfl_xor_sync(0xffffffffu, v, 8);
    v += __shfl_xor_sync(0xffffffffu, v, 4);
    v += __shfl_xor_sync(0xffffffffu, v, 2);
    v += __shfl_xor_sync(0xffffffffu, v, 1);
    return v;
#else
    return (double)x;
#endif
"""


@wp.func_native(_group_sum_snippet)
def group_sum_f64(x: wp.float32) -> wp.float64: ...


PREFETCH = 1  # drive samples loaded ahead of the step that uses them in the fused kernel: 1 was the fastest of 0/1/2/4 on the H100 (10.1 vs 11.1 / 10.5 / 11.8 ms, bench/results/transduction-h100-s7.json)


@functools.cache
def taxel_sum_kernel(n_prony: int, n_play: int, depth: int = PREFETCH, shuffle: bool = True, parts: bool = True,
                     approx: bool = APPROX_MATH):
    """The taxel chain with the whole-pad channel sum fused in (issue 16): one thread per (episode, taxel) as in
    `chain`, the episode's taxels padded to whole groups (CUDA: warps of 32 lanes; padding lanes rerun the last
    taxel and add nothing), and per step each group's conductance and stress sums (float64, fixed order) kept as
    one partial per (episode, group, step), written `group` steps at a time; `sum_parts` adds a row's partials in
    group order. No per-taxel
    conductance is written, and strain / stress only when asked (write_strain / write_stress). `depth` drive
    samples are loaded ahead of their step (0: at the step), so a thread has loads in flight while it computes.
    shuffle / parts = False leave out the group sums / the partials' stores: wrong sums, for timing only
    (bench/fused_variants.py). approx: as `taxel_kernels`."""
    k = taxel_kernels(n_prony, n_play, approx)
    Params, vec_p, vec_k, invariants_f, core_f = k["Params"], k["vec_p"], k["vec_k"], k["invariants"], k["core"]
    vec_d = wp.types.vector(length=max(depth, 1), dtype=wp.float32)

    def chain_sum(
        drive: wp.array(dtype=wp.float32),  # [E*T*N]
        n_steps: int,
        n_taxels: int,
        n_pad: int,  # threads per episode: n_taxels rounded up to whole groups
        group: int,  # lanes per partial sum: 32 on CUDA (a warp), 1 on the CPU
        mode: int,
        p: Params,
        st_strain: wp.array(dtype=wp.float32),  # [E*N] in/out
        st_phi: wp.array(dtype=wp.float32),
        st_prony: wp.array(dtype=vec_p),
        st_gap: wp.array(dtype=wp.float32),
        st_play: wp.array(dtype=vec_k),
        st_damage: wp.array(dtype=wp.float32),
        write_strain: int,
        write_stress: int,
        out_strain: wp.array(dtype=wp.float32),  # [E*T*N] (empty unless written)
        out_stress: wp.array(dtype=wp.float32),
        part_g: wp.array(dtype=wp.float64),  # [E * n_parts * T], n_parts = n_pad / group
        part_f: wp.array(dtype=wp.float64),
    ):
        tid = wp.tid()
        ep = tid // n_pad
        n = tid - ep * n_pad
        active = n < n_taxels
        nc = wp.min(n, n_taxels - 1)  # padding lanes load (and recompute) the episode's last taxel
        sid = ep * n_taxels + nc
        e = st_strain[sid]
        phi = st_phi[sid]
        h = st_prony[sid]
        s = st_gap[sid]
        z = st_play[sid]
        dmg = st_damage[sid]
        e_max, eb_sum, w_sum, phi_max = invariants_f(p)
        n_parts = n_pad // group
        w = n // group
        lane = n - w * group
        prow = (ep * n_parts + w) * n_steps
        base = ep * n_steps * n_taxels + nc
        last = wp.max(n_steps - 1, 0)
        buf = vec_d()
        mine_g = wp.float64(0.0)
        mine_f = wp.float64(0.0)
        j = int(0)
        if wp.static(depth > 0):
            if n_steps > 0:
                for i in range(depth):
                    buf[i] = drive[base + wp.min(i, last) * n_taxels]
        for kk in range(n_steps):
            idx = base + kk * n_taxels
            d = float(0.0)
            if wp.static(depth > 0):
                d = buf[0]
                for i in range(depth - 1):
                    buf[i] = buf[i + 1]
                buf[depth - 1] = drive[base + wp.min(kk + depth, last) * n_taxels]
            else:
                d = drive[idx]
            e, phi, h, s, z, dmg, sig, g = core_f(p, e_max, eb_sum, w_sum, phi_max, mode, d, e, phi, h, s, z, dmg)
            # no branch on `active` before the shuffles: a padding lane computes the last taxel bit for bit, so
            # its stores repeat that taxel's values; it adds zero to the sums
            if write_strain != 0:
                out_strain[idx] = e
            if write_stress != 0:
                out_stress[idx] = sig
            g32 = wp.where(active, g, 0.0)
            f32 = wp.where(active, sig, 0.0)
            gs = wp.float64(g32)
            fs = wp.float64(f32)
            if wp.static(shuffle):
                gs = group_sum_f64(g32)
                fs = group_sum_f64(f32)
            # lane j keeps the sums of step k0 + j (a select, no branch); every `group` steps the group writes
            # them at once, one coalesced store of `group` consecutive float64 per array; j counts up (no division)
            mine_g = wp.where(lane == j, gs, mine_g)
            mine_f = wp.where(lane == j, fs, mine_f)
            if wp.static(parts):
                if j == group - 1 or kk == n_steps - 1:
                    if lane <= j:
                        part_g[prow + kk - j + lane] = mine_g
                        part_f[prow + kk - j + lane] = mine_f
            j += 1
            if j == group:
                j = 0
        if active:
            st_strain[sid] = e
            st_phi[sid] = phi
            st_prony[sid] = h
            st_gap[sid] = s
            st_play[sid] = z
            st_damage[sid] = dmg

    chain_sum.__name__ = chain_sum.__qualname__ = (f"taxel_chain_sum_p{n_prony}_k{n_play}_d{depth}_s{int(shuffle)}{int(parts)}"
                                                   f"_a{int(approx)}")
    return wp.kernel(chain_sum, module="unique", enable_backward=False)


# Tried in session 12 and removed: the group sums taken four steps per warp exchange (12 shuffles per 4 steps
# against 36; the same pairs, the same bits, tested on the H100) measured slower, 12.19 ms against 10.62 ms for the
# fused kernel (four copies of the step in the loop body; bench/results/transduction-h100-s12.json, CHANGELOG).


@wp.kernel
def sum_parts(
    part_g: wp.array(dtype=wp.float64),  # [E * n_parts * T]
    part_f: wp.array(dtype=wp.float64),
    n_parts: int,
    n_steps: int,
    area: float,
    g_out: wp.array(dtype=wp.float64),  # [E*T]: the pad's conductance (one channel)
    force_out: wp.array(dtype=wp.float64),  # [E*T]
):
    r = wp.tid()  # (episode, step); neighbouring threads read neighbouring steps (coalesced)
    ep = r // n_steps
    k = r - ep * n_steps
    g = wp.float64(0.0)
    f = wp.float64(0.0)
    for j in range(n_parts):
        q = (ep * n_parts + j) * n_steps + k
        g += part_g[q]
        f += part_f[q]
    g_out[r] = g
    force_out[r] = f * wp.float64(area)


class TaxelChainWarp:
    """Holds device state for one batch shape and launches the kernels.

    drive: [E, T, N] float32 (numpy or a wp.array on `device`). State persists across `run` calls,
    so a long episode can be fed in chunks (streaming) with the same result as in one piece.
    """

    def __init__(self, p: TaxelParams, n_episodes: int, n_taxels: int, device: str = "cpu"):
        init_warp()
        self.p, self.E, self.N, self.device = p, n_episodes, n_taxels, resolve_device(device)
        self.k = taxel_kernels(p.n_prony, p.n_play)
        self.params = self._params()
        self.reset()

    def _params(self):
        p, k = self.p, self.k
        f32 = np.float32
        s = k["Params"]()
        s.prony_decay = k["vec_p"](*p.prony_decay.astype(f32))
        s.prony_eb = k["vec_p"](*(p.prony_modulus_pa * p.prony_gain).astype(f32))
        s.play_r = k["vec_k"](*p.play_threshold.astype(f32))
        s.play_w = k["vec_k"](*p.play_weight.astype(f32))
        s.e_inf = float(p.youngs_modulus_pa)
        s.e_lock = float(p.lock_strain)
        s.recovery = float(p.recovery_decay)
        s.softening = float(p.softening)
        s.net = network_struct(p.net)
        s.g0 = float(1.0 / p.rest_resistance_ohm)
        return s

    def reset(self, state: TaxelState | None = None) -> None:
        st = state or TaxelState.zeros(self.E * self.N, self.p)
        d = self.device
        self.st_strain = wp.array(st.strain, dtype=wp.float32, device=d)
        self.st_phi = wp.array(st.phi, dtype=wp.float32, device=d)
        self.st_prony = wp.array(st.prony_pa, dtype=self.k["vec_p"], device=d)
        self.st_gap = wp.array(st.gap_strain, dtype=wp.float32, device=d)
        self.st_play = wp.array(st.play, dtype=self.k["vec_k"], device=d)
        self.st_damage = wp.array(st.damage, dtype=wp.float32, device=d)

    def state(self) -> TaxelState:
        return TaxelState(
            self.st_strain.numpy(), self.st_phi.numpy(), self.st_prony.numpy(), self.st_gap.numpy(), self.st_play.numpy(),
            self.st_damage.numpy(),
        )

    def _state_args(self):
        return [self.st_strain, self.st_phi, self.st_prony, self.st_gap, self.st_play, self.st_damage]

    def run_device(self, drive: wp.array, n_steps: int, mode: int, outs: list | None = None):
        """Launch on a flat device array [E*T*N]; returns (strain, stress, conductance) device arrays."""
        size = self.E * n_steps * self.N
        out = outs or [wp.empty(size, dtype=wp.float32, device=self.device) for _ in range(3)]
        wp.launch(
            self.k["chain"], dim=self.E * self.N,
            inputs=[drive, n_steps, self.N, int(mode), self.params, *self._state_args(), out[0], out[1], out[2]],
            device=self.device,
        )
        return out

    def run_pad_device(self, drive: wp.array, n_steps: int, mode: int, area_m2: float, write_strain: bool = True,
                       write_stress: bool = True, group: int | None = None, depth: int = PREFETCH, outs: list | None = None):
        """The chain with the whole-pad channel sum fused in (`taxel_sum_kernel`) on a flat device array [E*T*N]:
        returns (strain or None, stress or None, pad conductance [E*T] float64, force [E*T] float64 = sum of the
        stress x area). group: lanes per partial sum (default 32 on CUDA, 1 on the CPU, where it is the plain
        per-row sum in taxel order). outs: [strain, stress, part_g, part_f] device buffers to reuse (sizes E*T*N
        float32 where written, E * n_parts * T float64), as `run_device`'s outs."""
        E, N, T, d = self.E, self.N, n_steps, self.device
        if group is None:
            group = WARP_LANES if wp.get_device(d).is_cuda else 1
        if wp.get_device(d).is_cuda and group != WARP_LANES:
            raise ValueError(f"on CUDA the partial sums are over warps of {WARP_LANES} lanes")
        n_pad = -(-N // group) * group
        n_parts = n_pad // group
        size = E * T * N
        empty = wp.empty(0, dtype=wp.float32, device=d)
        if outs is not None:
            strain, stress, part_g, part_f = outs
            strain, stress = (strain if write_strain else empty), (stress if write_stress else empty)
        else:
            strain = wp.empty(size, dtype=wp.float32, device=d) if write_strain else empty
            stress = wp.empty(size, dtype=wp.float32, device=d) if write_stress else empty
            part_g = wp.empty(E * n_parts * T, dtype=wp.float64, device=d)
            part_f = wp.empty(E * n_parts * T, dtype=wp.float64, device=d)
        wp.launch(
            taxel_sum_kernel(self.p.n_prony, self.p.n_play, depth), dim=E * n_pad,
            inputs=[drive, T, N, n_pad, group, int(mode), self.params, *self._state_args(), int(write_strain),
                    int(write_stress), strain, stress, part_g, part_f],
            device=d,
        )
        g = wp.empty(E * T, dtype=wp.float64, device=d)
        force = wp.empty(E * T, dtype=wp.float64, device=d)
        wp.launch(sum_parts, dim=E * T, inputs=[part_g, part_f, n_parts, T, float(area_m2), g, force], device=d)
        return (strain if write_strain else None, stress if write_stress else None, g, force)

    def run(self, drive: np.ndarray, mode: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """drive [E, T, N] -> strain, stress_pa, conductance_s, each [E, T, N] numpy float32."""
        E, T, N = drive.shape
        if (E, N) != (self.E, self.N):
            raise ValueError(f"drive shape {drive.shape} does not match this chain's (episodes={self.E}, taxels={self.N})")
        dev = wp.array(np.ascontiguousarray(drive, dtype=np.float32).reshape(-1), dtype=wp.float32, device=self.device)
        outs = self.run_device(dev, T, mode)
        return tuple(o.numpy().reshape(E, T, N) for o in outs)  # type: ignore[return-value]


@wp.kernel
def _divided_f32(field: wp.array2d(dtype=wp.float64), divisor: wp.float64, out: wp.array(dtype=wp.float32)):
    f, n = wp.tid()
    out[f * field.shape[1] + n] = wp.float32(field[f, n] / divisor)


def drive_on_device(field: wp.array, divisor: float) -> wp.array:
    """A float64 load field on the device, flat (E T, N) -> the chain's float32 drive [E*T*N] = field / divisor
    (the rounding of numpy's (field / divisor).astype(float32): strain = deformation / thickness)."""
    out = wp.empty(field.shape[0] * field.shape[1], dtype=wp.float32, device=field.device)
    wp.launch(_divided_f32, dim=field.shape, inputs=[field, wp.float64(divisor), out], device=field.device)
    return out


@wp.kernel
def _scaled(x: wp.array(dtype=wp.float32), scale: wp.float32, out: wp.array(dtype=wp.float32)):
    i = wp.tid()
    out[i] = x[i] * scale


def scaled_on_device(x: wp.array, scale: float, out: wp.array | None = None) -> wp.array:
    """x * float32(scale) for a flat float32 device array (numpy's x * np.float32(scale), bit for bit)."""
    out = wp.empty_like(x) if out is None else out
    wp.launch(_scaled, dim=x.shape[0], inputs=[x, wp.float32(scale), out], device=x.device)
    return out

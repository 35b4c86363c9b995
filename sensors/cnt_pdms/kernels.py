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
"""

# no `from __future__ import annotations`: Warp must see the closure types as real objects

import functools

import numpy as np
import warp as wp

from sensors.cnt_pdms.params import TaxelParams
from sensors.cnt_pdms.reference import MAX_STRAIN_FRACTION, TaxelState
from sensors.percolation import NetworkWp, conductance_ratio_wp, damage_wp, kinetics_wp, network_struct
from sensors.warp_setup import init_warp, resolve_device

@functools.cache
def taxel_kernels(n_prony: int, n_play: int):
    """Kernels and types for this many Prony terms and play operators; compiled once per pair."""
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

    def step(p: Params, mode: int, d: float, e: float, phi: float, h: vec_p, s: float, z: vec_k, dmg: float):
        e_max = strain_frac * p.e_lock
        eb_sum = float(0.0)
        w_sum = float(0.0)
        for i in range(n_prony):
            eb_sum += p.prony_eb[i]
        for j in range(n_play):
            w_sum += p.play_w[j]
        e_new = float(0.0)
        phi_new = float(0.0)
        m = 1.0 - p.softening * dmg
        if mode == 1:
            phi_max = e_max / (1.0 - e_max / p.e_lock)
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
        dmg_new = damage_wp(p.net, dmg, e_new)
        e_net = (1.0 - w_sum) * s_new
        z_new = z
        for j in range(n_play):
            zj = wp.max(s_new - p.play_r[j], wp.min(s_new + p.play_r[j], z[j]))
            zj = s_new + (zj - s_new) * p.recovery
            z_new[j] = zj
            e_net += p.play_w[j] * zj
        g = p.g0 * conductance_ratio_wp(p.net, e_net, dmg_new)
        return e_new, phi_new, h_new, s_new, z_new, dmg_new, sig, g

    step.__name__ = step.__qualname__ = f"taxel_step_p{n_prony}_k{n_play}"
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

    chain.__name__ = chain.__qualname__ = f"taxel_chain_p{n_prony}_k{n_play}"
    k_chain = wp.kernel(chain, module="unique", enable_backward=False)
    return {"chain": k_chain, "Params": Params, "vec_p": vec_p, "vec_k": vec_k}


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


def scaled_on_device(x: wp.array, scale: float) -> wp.array:
    """x * float32(scale) for a flat float32 device array (numpy's x * np.float32(scale), bit for bit)."""
    out = wp.empty_like(x)
    wp.launch(_scaled, dim=x.shape[0], inputs=[x, wp.float32(scale), out], device=x.device)
    return out

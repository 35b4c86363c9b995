"""Warp kernel of the per-taxel CNT-PDMS chain (same equations as sensors/taxel_ref.py, which tests compare).

One thread per (episode, taxel) loops over time with the whole state in registers (TECH-NOTES: one
launch with the time loop inside beats one launch per step by ~7x on the GPU). Memory layout [E, T, N]:
neighbouring threads read neighbouring taxels, so loads coalesce on CUDA.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from sensors.params import N_PLAY, N_PRONY, TaxelParams
from sensors.taxel_ref import MAX_STRAIN_FRACTION, TaxelState
from sensors.warp_setup import init_warp, resolve_device

vec_prony = wp.types.vector(length=N_PRONY, dtype=wp.float32)
vec_play = wp.types.vector(length=N_PLAY, dtype=wp.float32)


@wp.kernel
def taxel_chain_kernel(
    drive: wp.array(dtype=wp.float32),  # [E*T*N]
    n_steps: int,
    n_taxels: int,
    mode: int,
    prony_decay: vec_prony,
    prony_gain: vec_prony,
    prony_modulus: vec_prony,
    play_r: vec_play,
    play_w: vec_play,
    e_inf: float,
    e_lock: float,
    gap_a: float,
    gap_b: float,
    recovery: float,
    gamma: float,
    g0: float,
    st_strain: wp.array(dtype=wp.float32),  # [E*N] in/out
    st_phi: wp.array(dtype=wp.float32),
    st_prony: wp.array(dtype=vec_prony),
    st_gap: wp.array(dtype=wp.float32),
    st_play: wp.array(dtype=vec_play),
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

    e_max = float(MAX_STRAIN_FRACTION) * e_lock
    phi_max = e_max / (1.0 - e_max / e_lock)
    eb_sum = float(0.0)
    w_sum = float(0.0)
    for i in range(N_PRONY):
        eb_sum += prony_modulus[i] * prony_gain[i]
    for j in range(N_PLAY):
        w_sum += play_w[j]
    stiff = e_inf + eb_sum
    w_direct = 1.0 - w_sum

    base = ep * n_steps * n_taxels + n
    for k in range(n_steps):
        idx = base + k * n_taxels
        d = drive[idx]
        e_new = float(0.0)
        phi_new = float(0.0)
        if mode == 1:
            ah = float(0.0)
            for i in range(N_PRONY):
                ah += prony_decay[i] * h[i]
            phi_new = wp.clamp((d - ah + eb_sum * phi) / stiff, 0.0, phi_max)
            e_new = phi_new / (1.0 + phi_new / e_lock)
        else:
            e_new = wp.clamp(d, 0.0, e_max)
            phi_new = e_new / (1.0 - e_new / e_lock)
        sig = e_inf * phi_new
        dphi = phi_new - phi
        for i in range(N_PRONY):
            h[i] = prony_decay[i] * h[i] + prony_modulus[i] * prony_gain[i] * dphi
            sig += h[i]
        s = gap_a * s + (1.0 - gap_a) * e + (1.0 - gap_b) * (e_new - e)
        e_net = w_direct * s
        for j in range(N_PLAY):
            zj = wp.max(s - play_r[j], wp.min(s + play_r[j], z[j]))
            zj = s + (zj - s) * recovery
            z[j] = zj
            e_net += play_w[j] * zj
        g = g0 / ((1.0 - e_net) * wp.exp(-gamma * e_net))
        e = e_new
        phi = phi_new
        out_strain[idx] = e
        out_stress[idx] = sig
        out_cond[idx] = g

    st_strain[tid] = e
    st_phi[tid] = phi
    st_prony[tid] = h
    st_gap[tid] = s
    st_play[tid] = z


class TaxelChainWarp:
    """Holds device buffers for one batch shape and launches the fused kernel.

    drive: [E, T, N] float32 (numpy or a wp.array on `device`). State persists across `run` calls,
    so a long episode can be fed in chunks (streaming) with the same result as in one piece.
    """

    def __init__(self, p: TaxelParams, n_episodes: int, n_taxels: int, device: str = "cpu"):
        init_warp()
        self.p, self.E, self.N, self.device = p, n_episodes, n_taxels, resolve_device(device)
        self.reset()

    def reset(self, state: TaxelState | None = None) -> None:
        st = state or TaxelState.zeros(self.E * self.N)
        d = self.device
        self.st_strain = wp.array(st.strain, dtype=wp.float32, device=d)
        self.st_phi = wp.array(st.phi, dtype=wp.float32, device=d)
        self.st_prony = wp.array(st.prony_pa, dtype=vec_prony, device=d)
        self.st_gap = wp.array(st.gap_strain, dtype=wp.float32, device=d)
        self.st_play = wp.array(st.play, dtype=vec_play, device=d)

    def state(self) -> TaxelState:
        return TaxelState(
            self.st_strain.numpy(), self.st_phi.numpy(), self.st_prony.numpy(), self.st_gap.numpy(), self.st_play.numpy()
        )

    def run_device(self, drive: wp.array, n_steps: int, mode: int):
        """Launch on a flat device array [E*T*N]; returns (strain, stress, conductance) device arrays."""
        p, d = self.p, self.device
        size = self.E * n_steps * self.N
        out = [wp.empty(size, dtype=wp.float32, device=d) for _ in range(3)]
        wp.launch(
            taxel_chain_kernel,
            dim=self.E * self.N,
            inputs=[
                drive, n_steps, self.N, int(mode),
                vec_prony(*p.prony_decay.astype(np.float32)),
                vec_prony(*p.prony_gain.astype(np.float32)),
                vec_prony(*p.prony_modulus_pa.astype(np.float32)),
                vec_play(*p.play_threshold.astype(np.float32)),
                vec_play(*p.play_weight.astype(np.float32)),
                float(p.youngs_modulus_pa), float(p.lock_strain), float(p.gap_decay), float(p.gap_gain),
                float(p.recovery_decay), float(p.gamma_s0), float(1.0 / p.rest_resistance_ohm),
                self.st_strain, self.st_phi, self.st_prony, self.st_gap, self.st_play,
                out[0], out[1], out[2],
            ],
            device=d,
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

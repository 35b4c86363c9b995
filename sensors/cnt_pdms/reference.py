"""Numpy reference of the per-taxel CNT-PDMS chain; the Warp kernel in sensors/cnt_pdms/kernels.py must match it.

Per taxel and sample step (dt = 1 / sample rate), compressive strain e >= 0 and stress sigma >= 0:
  mechanics  sigma = m (E_inf phi(e) + sum_i h_i),  phi(e) = e / (1 - e/e_lock)    (nonlinear elastic law;
             m = 1 - softening D: Mullins stress softening by the network damage D of the previous step)
             h_i' = a_i h_i + E_i b_i (phi' - phi)   (generalized Maxwell / Prony, exponential integrator,
             exact for phi linear within a step; Ferry, Viscoelastic Properties of Polymers, 1980)
             displacement control: e is given -> sigma; force control: sigma is given -> phi' in closed form
  network    s' = first-order kinetics of the network strain toward e, tau_form loading / tau_break unloading;
             D' = Mullins-type damage (sensors/percolation.py: kinetics, damage)
  hysteresis z_k' = max(s' - r_k, min(s' + r_k, z_k)), then z_k' -> s' + (z_k' - s') c (slow recovery);
             e_net = (1 - sum w) s' + sum w_k z_k'   (Prandtl-Ishlinskii play bank, return-point memory;
             Brokate & Sprekels 1996)
  conduction G = G0 ratio(e_net, D')   (percolation paths x Simmons tunneling x path length; Hu et al. 2008;
             sensors/percolation.py)
Outputs are the strain, the stress and the conductance G = 1/R of every taxel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sensors.cnt_pdms.params import MODE_FORCE, TaxelParams
from sensors.percolation import conductance_ratio_numpy, damage_numpy, kinetics_numpy

MAX_STRAIN_FRACTION = 0.95  # of lock_strain: the law diverges at e_lock


@dataclass
class TaxelState:
    """State carried across calls, all float32. Shapes: [B] or [B, P] / [B, K]; B = episodes x taxels,
    P Prony terms, K play operators."""

    strain: np.ndarray
    phi: np.ndarray
    prony_pa: np.ndarray
    gap_strain: np.ndarray
    play: np.ndarray
    damage: np.ndarray  # Mullins-type network damage D (fresh sample: 0)

    @classmethod
    def zeros(cls, n: int, p: TaxelParams) -> TaxelState:
        z = np.zeros(n, np.float32)
        return cls(z.copy(), z.copy(), np.zeros((n, p.n_prony), np.float32), z.copy(), np.zeros((n, p.n_play), np.float32),
                   z.copy())


def _phi(e: np.ndarray, e_lock: float) -> np.ndarray:
    return e / (1.0 - e / e_lock)


def _phi_inv(phi: np.ndarray, e_lock: float) -> np.ndarray:
    return phi / (1.0 + phi / e_lock)


def taxel_chain_numpy(
    drive: np.ndarray, mode: int, p: TaxelParams, state: TaxelState | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, TaxelState]:
    """Run the chain over time.

    drive: [E, T, N] float32, compressive strain (mode 0) or compressive stress in Pa (mode 1).
    Returns strain [E,T,N], stress_pa [E,T,N], conductance_s [E,T,N] (siemens), final state (updated copy).
    Arithmetic in float32 like the Warp kernel.
    """
    f32 = np.float32
    E, T, N = drive.shape
    st = state if state is not None else TaxelState.zeros(E * N, p)
    e = st.strain.reshape(E, N).astype(f32).copy()
    phi = st.phi.reshape(E, N).astype(f32).copy()
    h = st.prony_pa.reshape(E, N, p.n_prony).astype(f32).copy()
    s = st.gap_strain.reshape(E, N).astype(f32).copy()
    z = st.play.reshape(E, N, p.n_play).astype(f32).copy()
    dmg = st.damage.reshape(E, N).astype(f32).copy()
    soft = f32(p.softening)

    a, b, Ei = (x.astype(f32) for x in (p.prony_decay, p.prony_gain, p.prony_modulus_pa))
    r, w = p.play_threshold.astype(f32), p.play_weight.astype(f32)
    e_inf, e_lock = f32(p.youngs_modulus_pa), f32(p.lock_strain)
    e_max = f32(MAX_STRAIN_FRACTION * p.lock_strain)
    phi_max = _phi(e_max, e_lock)
    rec = f32(p.recovery_decay)
    w_direct = f32(1.0) - w.sum(dtype=f32)
    g0 = f32(1.0 / p.rest_resistance_ohm)
    stiff = e_inf + (Ei * b).sum(dtype=f32)

    strain = np.empty((E, T, N), f32)
    stress = np.empty((E, T, N), f32)
    cond = np.empty((E, T, N), f32)
    for k in range(T):
        d = drive[:, k, :].astype(f32)
        m = f32(1.0) - soft * dmg
        if mode == MODE_FORCE:
            rhs = d / m - (a * h).sum(-1, dtype=f32) + (Ei * b).sum(dtype=f32) * phi
            phi_new = np.clip(rhs / stiff, f32(0.0), phi_max)
            e_new = _phi_inv(phi_new, e_lock)
        else:
            e_new = np.clip(d, f32(0.0), e_max)
            phi_new = _phi(e_new, e_lock)
        h = a * h + Ei * b * (phi_new - phi)[..., None]
        sig = m * (e_inf * phi_new + h.sum(-1, dtype=f32))
        s = kinetics_numpy(s, e, e_new, p.net)
        dmg = damage_numpy(dmg, e_new, p.net)
        z = np.maximum(s[..., None] - r, np.minimum(s[..., None] + r, z))
        z = s[..., None] + (z - s[..., None]) * rec
        e_net = w_direct * s + (w * z).sum(-1, dtype=f32)
        g = g0 * conductance_ratio_numpy(e_net, dmg, p.net)
        e, phi = e_new, phi_new
        strain[:, k], stress[:, k], cond[:, k] = e, sig, g
    out_state = TaxelState(
        e.reshape(-1), phi.reshape(-1), h.reshape(-1, p.n_prony), s.reshape(-1), z.reshape(-1, p.n_play), dmg.reshape(-1)
    )
    return strain, stress, cond, out_state

"""Numpy reference of the N-type element chain (paper key `ntype`); sensors/ntype/kernels.py must match it.

Per element and sample step (dt = 1 / sample rate), float32 like the Warp kernel:
  lag         q' = a q + (1 - a) F          a = exp(-dt / lag_time)   (standard linear solid creep,
              u = K^-1 ((1 - g) F + g q'): the instantaneous compliance is (1 - g) of the relaxed one;
              Ferry, Viscoelastic Properties of Polymers, 1980)
  mechanics   K = sum_j k_j n_j n_j^T + k_f I,  k_j = E S / l_j   (three pin-ended elastic columns + filler;
              Timoshenko & Goodier, Theory of Elasticity, 1970); u = K^-1 F (F: force on the element top,
              world frame, z up, so a press is F_z < 0)
  strain      e_j = max(n_j . u / l_j, e_min)   (ntype sect. 2.3: Delta l_i ~ displacement along the column;
              negative = compression)
  resistance  R_j = rho(e_j) l_j^2 (1 + e_j)^2 / V_j = R_j0 (1 + e_j)^2 exp(beta e_j)
              (ntype eq. 1 at constant volume, l' = l (1 + e); rho(e) = rho0 exp(beta e))
Column order: (R_x, R_y, R_z) = the paper's columns "3" (+45 deg), "1" (-45 deg), "2" (normal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NtypeParams:
    """Flat constants of the element chain (SI). Shapes in brackets."""

    normals: np.ndarray  # [3, 3] unit column directions (rows), order R_x, R_y, R_z
    lengths_m: np.ndarray  # [3]
    compliance: np.ndarray  # [3, 3] K^-1 (m/N)
    rest_ohm: np.ndarray  # [3] R_j0
    beta: float  # piezoresistive exponent of rho(e)
    min_strain: float
    lag_decay: float  # a = exp(-dt / lag_time)
    lag_fraction: float  # g


def ntype_chain_numpy(
    force: np.ndarray, p: NtypeParams, q0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """force [E, T, M, 3] (N, on the element tops, world frame, z up) -> displacement [E,T,M,3] (m),
    strain [E,T,M,3], resistance [E,T,M,3] (ohm), final lag state q [E*M, 3]."""
    f32 = np.float32
    E, T, M, _ = force.shape
    q = np.zeros((E, M, 3), f32) if q0 is None else q0.reshape(E, M, 3).astype(f32).copy()
    C = p.compliance.astype(f32)
    n = p.normals.astype(f32)
    inv_l = (f32(1.0) / p.lengths_m.astype(f32))
    r0 = p.rest_ohm.astype(f32)
    a, g, beta, emin = f32(p.lag_decay), f32(p.lag_fraction), f32(p.beta), f32(p.min_strain)
    disp = np.empty((E, T, M, 3), f32)
    strain = np.empty((E, T, M, 3), f32)
    res = np.empty((E, T, M, 3), f32)
    for k in range(T):
        F = force[:, k].astype(f32)
        q = a * q + (f32(1.0) - a) * F
        load = (f32(1.0) - g) * F + g * q
        u = load @ C.T
        e = np.maximum((u @ n.T) * inv_l, emin)
        one = f32(1.0) + e
        disp[:, k], strain[:, k], res[:, k] = u, e, r0 * one * one * np.exp(beta * e)
    return disp, strain, res, q.reshape(E * M, 3)

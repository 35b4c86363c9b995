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


def scan_kirchhoff_numpy(R: np.ndarray, upper: np.ndarray, lower: np.ndarray, U: int, L: int, scheme: str,
                         drive_v: float, switch_on_ohm: float, reference_ohm: float) -> np.ndarray:
    """Direct Kirchhoff reference of sensors/ntype/scan.py for one frame R [M, 3] (ohm): for each column, list
    every resistor of the circuit (the 3 M columns between wire nodes, the multiplexer and reference resistors
    from wire nodes to the source / ground nodes), stamp them one by one into the nodal matrix with the source
    and ground as extra nodes, fix those two potentials and solve; then read the scheme's quantity.
    Source: D'Alessio, Sens. Actuators A 72 (1999) 71-76."""
    M = R.shape[0]
    src, gnd = U + L, U + L + 1
    cols = [(int(upper[m, j]), U + int(lower[m, j]), float(R[m, j])) for m in range(M) for j in range(3)]
    out = np.empty((M, 3))
    for m in range(M):
        for j in range(3):
            u, l = int(upper[m, j]), U + int(lower[m, j])
            res = list(cols)
            for w in range(U + L):
                if w == u:
                    res.append((w, src, switch_on_ohm))
                elif w == l:
                    extra = 0.0 if scheme == "feedback" else reference_ohm
                    res.append((w, gnd, switch_on_ohm + extra))
                elif scheme in ("grounded", "feedback"):
                    res.append((w, gnd, switch_on_ohm))
            n = U + L + 2
            A = np.zeros((n, n))
            for a, b, r in res:
                g = 1.0 / max(r, 1e-9)
                A[a, a] += g
                A[b, b] += g
                A[a, b] -= g
                A[b, a] -= g
            # Dirichlet rows for the source and ground nodes
            rhs = np.zeros(n)
            for node, pot in ((src, drive_v), (gnd, 0.0)):
                A[node] = 0.0
                A[node, node] = 1.0
                rhs[node] = pot
            v = np.linalg.solve(A, rhs)
            if scheme == "feedback":
                i = (v[l] - v[gnd]) / max(switch_on_ohm, 1e-9)
                out[m, j] = drive_v / i
            else:
                v_out = v[l] * reference_ohm / (switch_on_ohm + reference_ohm)
                out[m, j] = reference_ohm * (drive_v - v_out) / v_out
    return out

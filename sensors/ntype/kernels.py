"""Warp kernel of the N-type element chain (same equations as sensors/ntype/reference.py, which tests compare).

One thread per (episode, element) loops over time with the lag state in registers (TECH-NOTES: the time
loop inside one launch). Layout [E, T, M, 3] flattened; vectors are wp.vec3.
Source: paper key `ntype` sect. 2.3; Timoshenko & Goodier (1970) for the column elasticity.
"""

# no `from __future__ import annotations`: Warp must see the types as real objects


import numpy as np
import warp as wp

from sensors.ntype.reference import NtypeParams
from sensors.warp_setup import init_warp, resolve_device


@wp.struct
class NtypeWarpParams:
    normals: wp.mat33  # rows = column directions
    inv_len: wp.vec3
    compliance: wp.mat33
    rest: wp.vec3
    beta: float
    min_strain: float
    lag_decay: float
    lag_fraction: float


@wp.kernel(enable_backward=False)
def ntype_chain_kernel(
    force: wp.array(dtype=wp.vec3),  # [E*T*M]
    n_steps: int,
    n_elem: int,
    p: NtypeWarpParams,
    st_q: wp.array(dtype=wp.vec3),  # [E*M] in/out
    out_disp: wp.array(dtype=wp.vec3),
    out_strain: wp.array(dtype=wp.vec3),
    out_res: wp.array(dtype=wp.vec3),
):
    tid = wp.tid()
    ep = tid // n_elem
    m = tid - ep * n_elem
    q = st_q[tid]
    base = ep * n_steps * n_elem + m
    for k in range(n_steps):
        idx = base + k * n_elem
        F = force[idx]
        q = p.lag_decay * q + (1.0 - p.lag_decay) * F
        u = p.compliance * ((1.0 - p.lag_fraction) * F + p.lag_fraction * q)
        e = wp.cw_mul(p.normals * u, p.inv_len)
        e = wp.vec3(wp.max(e[0], p.min_strain), wp.max(e[1], p.min_strain), wp.max(e[2], p.min_strain))
        r = wp.vec3(0.0)
        for j in range(3):
            one = 1.0 + e[j]
            r[j] = p.rest[j] * one * one * wp.exp(p.beta * e[j])
        out_disp[idx] = u
        out_strain[idx] = e
        out_res[idx] = r
    st_q[tid] = q


def _params(p: NtypeParams) -> NtypeWarpParams:
    s = NtypeWarpParams()
    f = np.float32
    s.normals = wp.mat33(*p.normals.astype(f).ravel())
    s.inv_len = wp.vec3(*(1.0 / p.lengths_m).astype(f))
    s.compliance = wp.mat33(*p.compliance.astype(f).ravel())
    s.rest = wp.vec3(*p.rest_ohm.astype(f))
    s.beta, s.min_strain = float(p.beta), float(p.min_strain)
    s.lag_decay, s.lag_fraction = float(p.lag_decay), float(p.lag_fraction)
    return s


def ntype_chain_warp(force: np.ndarray, p: NtypeParams, device: str = "cpu", q0: np.ndarray | None = None):
    """force [E, T, M, 3] -> displacement, strain, resistance [E, T, M, 3] float32, final state q [E*M, 3]."""
    init_warp()
    device = resolve_device(device)
    E, T, M, _ = force.shape
    f = wp.array(np.ascontiguousarray(force, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)
    q = np.zeros((E * M, 3), np.float32) if q0 is None else np.asarray(q0, np.float32)
    st = wp.array(q, dtype=wp.vec3, device=device)
    outs = [wp.empty(E * T * M, dtype=wp.vec3, device=device) for _ in range(3)]
    wp.launch(ntype_chain_kernel, dim=E * M, inputs=[f, T, M, _params(p), st, *outs], device=device)
    d, s, r = (o.numpy().reshape(E, T, M, 3) for o in outs)
    return d, s, r, st.numpy()

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


# ------------------------------------------------------------------------------------------ scanned readout
# The "feedback" scan of sensors/ntype/scan.py (its numpy path is the reference; tests compare at 1e-9). One
# thread per frame, float64 in thread-local matrices (sizes fixed per wire count, one compiled kernel each):
#   assemble  the Schur complement of the crossbar's nodal matrix on the lower wires,
#             S = D_l - G^T D_u^-1 G (D = diag(g_on + wire conductances)), with the right-hand sides
#             B^T = G^T D_u^-1 beside it: [S | B^T], L x (L + U); S as rank-1 updates over the upper wires
#   solve     S X = B^T by Gaussian elimination with partial pivoting, then back substitution (rank-1 form)
#   read      R_app = 1 / (g_on^2 X[l, u]) for every column (u, l) (R = drive_v / I, I = g_on^2 drive_v X)
# Inner loops run over whole rows with fixed bounds (the compiler vectorises them; bounds that follow the pivot,
# or a triangle-then-mirror assembly of the symmetric S, measured 1.4-2x slower on the CPU device).
# Source: D'Alessio, Sens. Actuators A 72 (1999) 71-76 (zero-potential feedback); Golub & Van Loan, Matrix
# Computations (2013) sect. 3.4 (partial pivoting).
SCAN_CHUNK = 65536  # frames per launch
_SCAN_KERNELS: dict = {}


def _scan_feedback_kernel(U: int, L: int):
    """The feedback-scan kernel for U upper and L lower wires (compiled once per size, then cached)."""
    key = (U, L)
    if key in _SCAN_KERNELS:
        return _SCAN_KERNELS[key]
    NC = L + U
    Amat = wp.types.matrix(shape=(L, NC), dtype=wp.float64)
    Gmat = wp.types.matrix(shape=(U, L), dtype=wp.float64)
    Uvec = wp.types.vector(U, dtype=wp.float64)

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 0, "optimization_level": 3})
    def scan_feedback_kernel(
        R: wp.array2d(dtype=wp.float64),  # [F, C] column resistances (ohm), C = 3 M
        up: wp.array(dtype=wp.int32),  # [C] upper wire of each column
        lo: wp.array(dtype=wp.int32),  # [C] lower wire of each column
        g_on: wp.float64,  # multiplexer on-conductance (S)
        out: wp.array2d(dtype=wp.float64),  # [F, C] apparent resistances (ohm)
    ):
        f = wp.tid()
        n_col = R.shape[1]
        zero = wp.float64(0.0)
        one = wp.float64(1.0)
        G = Gmat()
        A = Amat()
        inv_du = Uvec()
        for c in range(n_col):
            G[up[c], lo[c]] = one / R[f, c]
        for l in range(L):
            A[l, l] = g_on
        for u in range(U):
            s = g_on
            for l in range(L):
                g = G[u, l]
                s += g
                A[l, l] = A[l, l] + g
            inv_du[u] = one / s
        for u in range(U):
            iu = inv_du[u]
            for l in range(L):
                b = G[u, l] * iu
                A[l, L + u] = b
                if b != zero:
                    for k in range(L):
                        A[l, k] = A[l, k] - b * G[u, k]
        # forward elimination with partial pivoting (S is symmetric and diagonally dominant, so no row swaps
        # happen in practice; the search stays for generality)
        for c in range(L):
            p = c
            best = wp.abs(A[c, c])
            for r in range(c + 1, L):
                v = wp.abs(A[r, c])
                if v > best:
                    best = v
                    p = r
            if p != c:
                for j in range(NC):
                    t = A[c, j]
                    A[c, j] = A[p, j]
                    A[p, j] = t
            ip = one / A[c, c]
            for r in range(c + 1, L):
                m = A[r, c] * ip
                # whole rows (fixed bounds vectorise; measured faster than j > c): columns j <= c of rows below
                # the pivot are the eliminated triangle, never read again
                for j in range(NC):
                    A[r, j] = A[r, j] - m * A[c, j]
        # back substitution, rank-1 form: x_k = A[k, L:] / A[k, k]; the rows above lose A[r, k] x_k
        for i in range(L):
            k = L - 1 - i
            ik = one / A[k, k]
            for j in range(L, NC):
                A[k, j] = A[k, j] * ik
            for r in range(k):
                a = A[r, k]
                for j in range(L, NC):
                    A[r, j] = A[r, j] - a * A[k, j]
        for c in range(n_col):
            out[f, c] = one / (g_on * g_on * A[lo[c], L + up[c]])

    _SCAN_KERNELS[key] = scan_feedback_kernel
    return scan_feedback_kernel


def scan_feedback_warp(R: np.ndarray, upper: np.ndarray, lower: np.ndarray, U: int, L: int, switch_on_ohm: float,
                       device: str = "cpu") -> np.ndarray:
    """R [F, M, 3] (ohm) -> apparent resistances [F, M, 3] float64 of the "feedback" scan (see above; the numpy
    reference is sensors/ntype/scan.py _scan_chunk). drive_v drops out of R_app = drive_v / I."""
    init_warp()
    device = resolve_device(device)
    F, M, _ = R.shape
    C = 3 * M
    Rf = np.ascontiguousarray(R, np.float64).reshape(F, C)
    g_on = 1.0 / max(float(switch_on_ohm), 1e-9)  # as the numpy path: R_on = 0 is an ideal switch
    kern = _scan_feedback_kernel(U, L)
    args = [wp.array(np.ascontiguousarray(a.ravel(), np.int32), dtype=wp.int32, device=device) for a in (upper, lower)]
    out = np.empty((F, C))
    for a in range(0, F, SCAN_CHUNK):
        b = min(F, a + SCAN_CHUNK)
        r = wp.array(Rf[a:b], dtype=wp.float64, device=device, copy=False)
        o = wp.empty((b - a, C), dtype=wp.float64, device=device)
        wp.launch(kern, dim=b - a, inputs=[r, *args, wp.float64(g_on), o], device=device)
        if b - a == F:
            return o.numpy().reshape(F, M, 3)  # one chunk: no copy on the CPU device
        out[a:b] = o.numpy()
    return out.reshape(F, M, 3)


# ------------------------------------------------------------------------------------------ element loads
# `NtypeSensor.loads` on fields left on the device (the GPU path): per frame and element, the label (the sum of the
# taxel forces the element's cell holds) and the electrode force (the cover influence, Boussinesq through the cover
# layer: sensors/ntype/model.py `cover_influence`) over the taxels in order. float64 like the numpy einsums, which
# sum in another order (BLAS): equal to ~1e-15 relative (tests/test_ntype.py).


@wp.kernel(enable_backward=False)
def ntype_loads_kernel(
    shear: wp.array3d(dtype=wp.float64),  # [F, N, 2] Pa
    pressure: wp.array2d(dtype=wp.float64),  # [F, N] Pa
    area: wp.float64,
    owner: wp.array(dtype=wp.int32),  # [N] element of each taxel
    influence: wp.array3d(dtype=wp.float64),  # [3, M, N]
    labels: wp.array3d(dtype=wp.float64),  # [F, M, 3] out
    elec: wp.array3d(dtype=wp.float64),  # [F, M, 3] out, world frame z up (a press pushes the electrode down)
):
    f, m = wp.tid()
    zero = wp.float64(0.0)
    lx = zero
    ly = zero
    lz = zero
    ex = zero
    ey = zero
    ez = zero
    for n in range(pressure.shape[1]):
        fx = shear[f, n, 0] * area
        fy = shear[f, n, 1] * area
        fz = pressure[f, n] * area
        if owner[n] == m:
            lx += fx
            ly += fy
            lz += fz
        ex += influence[0, m, n] * fx
        ey += influence[1, m, n] * fy
        ez += influence[2, m, n] * fz
    labels[f, m, 0] = lx
    labels[f, m, 1] = ly
    labels[f, m, 2] = lz
    elec[f, m, 0] = ex
    elec[f, m, 1] = ey
    elec[f, m, 2] = -ez


def ntype_loads_warp(shear, pressure, area_m2: float, owner: np.ndarray, influence: np.ndarray, frames: tuple[int, int]):
    """(labels, electrode forces) [E, T, M, 3] float64 numpy of taxel fields left on the device: shear (E T, N, 2)
    and pressure (E T, N) float64 Warp arrays; owner [N], influence [3, M, N] as in `NtypeSensor`."""
    E, T = frames
    F, M = E * T, influence.shape[1]
    device = pressure.device
    with wp.ScopedDevice(device):
        lab, el = wp.empty((F, M, 3), dtype=wp.float64), wp.empty((F, M, 3), dtype=wp.float64)
        wp.launch(ntype_loads_kernel, dim=(F, M), inputs=[
            shear.reshape((F, -1, 2)), pressure.reshape((F, -1)), wp.float64(area_m2),
            wp.array(np.asarray(owner, np.int32), dtype=wp.int32), wp.array(np.ascontiguousarray(influence, np.float64), dtype=wp.float64),
            lab, el])
        return lab.numpy().reshape(E, T, M, 3), el.numpy().reshape(E, T, M, 3)

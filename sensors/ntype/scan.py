"""Scanned readout of the N-type array: a passive resistor matrix solved by nodal analysis, batched over frames.

Source: D'Alessio, "Measurement errors in the scanning of piezoresistive sensors arrays", Sens. Actuators A 72
(1999) 71-76 (sneak paths, grounded lines, zero-potential feedback); the wiring is our reading of ntype sect. 2.2,
Figure 1: every element has two upper electrodes ("4", "5") and two lower ones ("6", "7") on wires ("8", "9")
that cross at right angles, and every column joins one upper to one lower wire:

    upper wires  u = 2 iy + a   (a = 0: electrode 4, shared by columns 1 and 2; a = 1: electrode 5, column 3)
    lower wires  l = 2 ix + b   (b = 0: electrode 6, column 1; b = 1: electrode 7, shared by columns 2 and 3)
    column 3 (R_x): (2 iy + 1, 2 ix + 1)   column 1 (R_y): (2 iy, 2 ix)   column 2 (R_z): (2 iy, 2 ix + 1)

so a 6 x 6 array is a 12 x 12 crossbar with 108 resistors (the (5, 6) crossing of each element is open).

Reading column (u, l): every wire w is tied through a conductance g_w to a potential E_w (the multiplexer);
the node voltages v of the U + L wires solve (Laplacian of the crossbar + diag g) v = g E. Schemes
(scenes/ntype_config.py NtypeReadoutConfig.scan):
  floating   wire u to drive_v and wire l to ground through R_on (+ R_ref on l); the others open
  grounded   every other wire to ground through R_on; wire l through R_on + R_ref; divider read at R_ref
  feedback   every wire to ground through R_on, wire u to drive_v; the current of wire l into the op-amp's
             virtual ground is read (R = drive_v / I)
The apparent resistance is what an instrument that assumes the selected column alone would compute. "feedback"
has one matrix per frame (only the right-hand side follows the selection), "grounded" one per lower wire,
"floating" one per column.
"""

from __future__ import annotations

import numpy as np

SCHEMES = ("ideal", "floating", "grounded", "feedback")
MAX_SYSTEMS = 200_000  # linear systems per batched solve (memory: MAX_SYSTEMS x (U + L)^2 float64)


def wire_map(elements_x: int, elements_y: int) -> tuple[np.ndarray, np.ndarray, int, int]:
    """(upper [M, 3], lower [M, 3], U, L): the wires of columns (R_x, R_y, R_z) of element m = iy * nx + ix."""
    iy, ix = np.divmod(np.arange(elements_x * elements_y), elements_x)
    upper = np.stack([2 * iy + 1, 2 * iy, 2 * iy], 1)
    lower = np.stack([2 * ix + 1, 2 * ix, 2 * ix + 1], 1)
    return upper, lower, 2 * elements_y, 2 * elements_x


def crossbar(R: np.ndarray, upper: np.ndarray, lower: np.ndarray, U: int, L: int) -> np.ndarray:
    """R [F, M, 3] (ohm) -> conductance matrix G [F, U, L] (S; 0 where no column)."""
    G = np.zeros((R.shape[0], U, L))
    G[:, upper.ravel(), lower.ravel()] = 1.0 / R.reshape(R.shape[0], -1)
    return G


def _laplacian(G: np.ndarray) -> np.ndarray:
    """[F, U + L, U + L] nodal conductance matrix of the bipartite crossbar."""
    F, U, L = G.shape
    A = np.zeros((F, U + L, U + L))
    A[:, :U, U:] = -G
    A[:, U:, :U] = -np.swapaxes(G, 1, 2)
    idx = np.arange(U + L)
    A[:, idx, idx] = np.concatenate([G.sum(2), G.sum(1)], 1)
    return A


def scan_apparent(R: np.ndarray, elements_x: int, elements_y: int, scheme: str, drive_v: float,
                  switch_on_ohm: float, reference_ohm: float, backend: str = "numpy",
                  device: str = "cpu") -> np.ndarray:
    """Apparent resistances [..., M, 3] (ohm) that the scan reads for true column resistances R [..., M, 3]
    (float64 batched solves; frames are independent). backend "warp" solves the default "feedback" scheme in
    a Warp kernel (sensors/ntype/kernels.py scan_feedback_warp, one thread per frame, tests compare it with
    this numpy path); "floating" and "grounded" (comparison options) always take the numpy path."""
    if scheme not in SCHEMES:
        raise ValueError(f"scan scheme '{scheme}' (allowed: {', '.join(SCHEMES)})")
    R = np.asarray(R, np.float64)
    if scheme == "ideal":
        return R.copy()
    shape = R.shape
    Rf = R.reshape(-1, shape[-2], 3)
    upper, lower, U, L = wire_map(elements_x, elements_y)
    if backend == "warp" and scheme == "feedback":
        from sensors.ntype.kernels import scan_feedback_warp

        return scan_feedback_warp(Rf, upper, lower, U, L, switch_on_ohm, device).reshape(shape)
    N = U + L
    per = {"feedback": 1, "grounded": L, "floating": U * L}[scheme]
    step = max(1, MAX_SYSTEMS // per)
    out = np.empty_like(Rf)
    for a in range(0, len(Rf), step):
        out[a : a + step] = _scan_chunk(Rf[a : a + step], upper, lower, U, L, N, scheme, drive_v, switch_on_ohm,
                                        reference_ohm)
    return out.reshape(shape)


def _scan_chunk(R, upper, lower, U, L, N, scheme, vs, r_on, r_ref):
    F = R.shape[0]
    g_on = 1.0 / max(r_on, 1e-9)  # R_on = 0: an ideal switch (stiff but exact in float64 at 1e-9 ohm)
    g_read = 1.0 / (r_on + r_ref)
    idx = np.arange(N)
    u_sel, l_sel = upper.ravel(), lower.ravel()  # [M*3] selections, in output order
    if scheme == "feedback":
        # one matrix per frame, [[D_u, -G], [-G^T, D_l]] with D = diag(wire conductances + g_on); the lower
        # wires' voltages with upper wire u driven are g_on vs (S^-1 G^T D_u^-1)[:, u], S = D_l - G^T D_u^-1 G
        # (the Schur complement, half the size of the full system)
        G = crossbar(R, upper, lower, U, L)
        du = G.sum(2) + g_on  # [F, U]
        dl = G.sum(1) + g_on  # [F, L]
        Bt = np.swapaxes(G, 1, 2) / du[:, None, :]  # [F, L, U] = G^T D_u^-1
        S = -Bt @ G
        S[:, np.arange(L), np.arange(L)] += dl
        X = np.linalg.solve(S, Bt)
        V = g_on * vs * X  # [F, L, U]: lower-wire voltages with upper wire u driven
        I = g_on * V[:, l_sel, u_sel]  # current of the read wire into the virtual ground
        return (vs / I).reshape(F, -1, 3)
    A0 = _laplacian(crossbar(R, upper, lower, U, L))
    if scheme == "grounded":
        A = np.repeat(A0[:, None], L, 1)  # [F, L, N, N]: one matrix per read (lower) wire
        A[..., idx, idx] += g_on
        A[:, np.arange(L), U + np.arange(L), U + np.arange(L)] += g_read - g_on
        B = np.zeros((F, L, N, U))
        B[:, :, np.arange(U), np.arange(U)] = g_on * vs
        V = np.linalg.solve(A, B)  # [F, L, N, U]
        v_out = V[:, l_sel, U + l_sel, u_sel] * (r_ref / (r_on + r_ref))
        return (r_ref * (vs - v_out) / v_out).reshape(F, -1, 3)
    # floating: one matrix per selected column
    S = len(u_sel)
    A = np.repeat(A0[:, None], S, 1)  # [F, S, N, N]
    s = np.arange(S)
    A[:, s, u_sel, u_sel] += g_on
    A[:, s, U + l_sel, U + l_sel] += g_read
    b = np.zeros((F, S, N, 1))
    b[:, s, u_sel, 0] = g_on * vs
    V = np.linalg.solve(A, b)[..., 0]  # [F, S, N]
    v_out = V[:, s, U + l_sel] * (r_ref / (r_on + r_ref))
    return (r_ref * (vs - v_out) / v_out).reshape(F, -1, 3)

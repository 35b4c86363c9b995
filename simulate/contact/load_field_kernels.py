"""Warp kernels of the taxel load field: the same fields as `simulate.contact.load_field` (its numpy
reference, tested equal), for the GPU path where the numpy version would be the host's largest cost.

Model (see simulate/contact/load_field.py): indenter overlap per taxel cell (box: exact cell coverage; sphere:
supersampled), spread by the separable Gaussian thin-layer kernel (Johnson, Contact Mechanics, 1985,
sect. 5.8), deformation = max(overlap, spread), Winkler pressure share of the net normal force, shear
with the same weights; a force with no resolvable overlap goes to a Gaussian at the indenter centre.
Frames F = E x T are flat; float64 throughout, like the reference.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from scenes.config import SceneConfig
from sensors.taxels import SPHERE_SUPERSAMPLE, spread_matrix, taxel_area_m2, taxel_centres_1d, taxel_xy_m


@wp.kernel
def _overlap_box(pos: wp.array2d(dtype=wp.float64), xc: wp.array(dtype=wp.float64), yc: wp.array(dtype=wp.float64),
                 px: wp.float64, py: wp.float64, hx: wp.float64, hy: wp.float64, out: wp.array2d(dtype=wp.float64)):
    f, n = wp.tid()
    nx = xc.shape[0]
    ix = n % nx
    iy = n // nx
    pen = wp.max(-pos[f, 2], wp.float64(0.0))
    half = wp.float64(0.5)
    cx = wp.max(wp.min(pos[f, 0] + hx, xc[ix] + half * px) - wp.max(pos[f, 0] - hx, xc[ix] - half * px), wp.float64(0.0)) / px
    cy = wp.max(wp.min(pos[f, 1] + hy, yc[iy] + half * py) - wp.max(pos[f, 1] - hy, yc[iy] - half * py), wp.float64(0.0)) / py
    out[f, n] = pen * cy * cx


@wp.kernel
def _overlap_sphere(pos: wp.array2d(dtype=wp.float64), xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64),
                    nx: int, s: int, radius: wp.float64, out: wp.array2d(dtype=wp.float64)):
    f, n = wp.tid()
    ix = n % nx
    iy = n // nx
    pen = -pos[f, 2]
    r2 = radius * radius
    acc = wp.float64(0.0)
    for a in range(s):
        dy = ys[iy * s + a] - pos[f, 1]
        for b in range(s):
            dx = xs[ix * s + b] - pos[f, 0]
            rr = dy * dy + dx * dx
            if rr < r2:
                acc += wp.max(pen - radius + wp.sqrt(r2 - rr), wp.float64(0.0))
    out[f, n] = acc / wp.float64(s * s)


@wp.kernel
def _spread_x(ov: wp.array2d(dtype=wp.float64), sx: wp.array2d(dtype=wp.float64), tmp: wp.array2d(dtype=wp.float64)):
    """tmp[f, iy, ix] = sum_k ov[f, iy, k] sx[ix, k]"""
    f, n = wp.tid()
    nx = sx.shape[0]
    ix = n % nx
    row = n - ix
    acc = wp.float64(0.0)
    for k in range(nx):
        acc += ov[f, row + k] * sx[ix, k]
    tmp[f, n] = acc


@wp.kernel
def _spread_y_max(ov: wp.array2d(dtype=wp.float64), tmp: wp.array2d(dtype=wp.float64), sy: wp.array2d(dtype=wp.float64),
                  nx: int, deform: wp.array2d(dtype=wp.float64)):
    """deform = max(overlap, sum_j sy[iy, j] tmp[f, j, ix])"""
    f, n = wp.tid()
    ix = n % nx
    iy = n // nx
    acc = wp.float64(0.0)
    for j in range(sy.shape[0]):
        acc += sy[iy, j] * tmp[f, j * nx + ix]
    deform[f, n] = wp.max(ov[f, n], acc)


@wp.kernel
def _distribute(deform: wp.array2d(dtype=wp.float64), pos: wp.array2d(dtype=wp.float64), force: wp.array2d(dtype=wp.float64),
                txy: wp.array2d(dtype=wp.float64), area: wp.float64, sigma: wp.float64,
                pressure: wp.array2d(dtype=wp.float64), shear: wp.array3d(dtype=wp.float64)):
    """Per frame: Winkler share of the normal force (weights = deformation, or the centre Gaussian)."""
    f = wp.tid()
    N = deform.shape[1]
    zero = wp.float64(0.0)
    fn = wp.max(force[f, 2], zero)
    wsum = zero
    for n in range(N):
        wsum += deform[f, n]
    gauss = fn > zero and wsum <= zero
    if gauss:
        wsum = zero
        for n in range(N):
            dx = txy[n, 0] - pos[f, 0]
            dy = txy[n, 1] - pos[f, 1]
            wsum += wp.exp(-(dx * dx + dy * dy) / (wp.float64(2.0) * sigma * sigma))
    scale = zero
    if fn > zero:
        if wsum > zero:
            scale = wp.float64(1.0) / (area * wsum)
        else:
            scale = wp.float64(1.0) / area
    for n in range(N):
        w = deform[f, n]
        if gauss:
            dx = txy[n, 0] - pos[f, 0]
            dy = txy[n, 1] - pos[f, 1]
            w = wp.exp(-(dx * dx + dy * dy) / (wp.float64(2.0) * sigma * sigma))
        share = w * scale
        pressure[f, n] = share * fn
        shear[f, n, 0] = share * force[f, 0]
        shear[f, n, 1] = share * force[f, 1]


def load_field_warp(cfg: SceneConfig, pos_rel_m: np.ndarray, force_n: np.ndarray, device: str, to_host: bool = True):
    """Same contract as simulate.contact.load_field (shapes (E, T, 3) in; deformation_m, pressure_pa
    (E, T, N) and shear_pa (E, T, N, 2) out, float64), computed by Warp kernels on `device`.
    to_host=False: the outputs stay on the device as Warp arrays, flat over frames: (E T, N), (E T, N, 2)."""
    pad, ind = cfg.pad, cfg.indenter
    E, T, _ = pos_rel_m.shape
    F, nx, ny = E * T, pad.taxels_x, pad.taxels_y
    N = nx * ny
    f64 = wp.float64

    def arr(x, shape=None):
        return wp.array(np.ascontiguousarray(x, np.float64).reshape(shape or np.shape(x)), dtype=f64, device=device)

    with wp.ScopedDevice(device):
        pos, force = arr(pos_rel_m, (F, 3)), arr(force_n, (F, 3))
        ov = wp.empty((F, N), dtype=f64)
        if ind.shape == "box":
            xc, yc = arr(taxel_centres_1d(pad.size_x_m, nx)), arr(taxel_centres_1d(pad.size_y_m, ny))
            wp.launch(_overlap_box, dim=(F, N), inputs=[pos, xc, yc, f64(pad.size_x_m / nx), f64(pad.size_y_m / ny),
                                                        f64(ind.size_x_m / 2), f64(ind.size_y_m / 2), ov])
        else:
            s = SPHERE_SUPERSAMPLE
            xs, ys = arr(taxel_centres_1d(pad.size_x_m, nx * s)), arr(taxel_centres_1d(pad.size_y_m, ny * s))
            wp.launch(_overlap_sphere, dim=(F, N), inputs=[pos, xs, ys, nx, s, f64(ind.radius_m), ov])
        sx = arr(spread_matrix(pad.size_x_m, nx, pad.spread_length_m))
        sy = arr(spread_matrix(pad.size_y_m, ny, pad.spread_length_m))
        tmp, deform = wp.empty((F, N), dtype=f64), wp.empty((F, N), dtype=f64)
        wp.launch(_spread_x, dim=(F, N), inputs=[ov, sx, tmp])
        wp.launch(_spread_y_max, dim=(F, N), inputs=[ov, tmp, sy, nx, deform])
        pressure, shear = wp.empty((F, N), dtype=f64), wp.empty((F, N, 2), dtype=f64)
        wp.launch(_distribute, dim=F, inputs=[deform, pos, force, arr(taxel_xy_m(cfg)), f64(taxel_area_m2(cfg)),
                                              f64(pad.spread_length_m), pressure, shear])
        if not to_host:
            return deform, pressure, shear
        return deform.numpy().reshape(E, T, N), pressure.numpy().reshape(E, T, N), shear.numpy().reshape(E, T, N, 2)


@wp.kernel
def _to_f32(src: wp.array(dtype=wp.float64), dst: wp.array(dtype=wp.float32)):
    i = wp.tid()
    dst[i] = wp.float32(src[i])


@wp.kernel
def _flag_blocks(bits: wp.array(dtype=wp.uint32), per_row: int, per_taxel: int, n_taxels: int, block: int,
                 n_blocks: int, flags: wp.array(dtype=wp.int32)):
    """flags[r * n_blocks + b] = 1 where a float32 of row r's block b has a non-zero bit (-0.0 and NaN count, as
    in the writers' zero-chunk test); racing stores all write 1."""
    i = wp.tid()
    if bits[i] != wp.uint32(0):
        r = i // per_row
        n = (i // per_taxel) % n_taxels
        flags[r * n_blocks + n // block] = 1


@wp.kernel
def _gather_blocks(src: wp.array(dtype=wp.float32), index: wp.array2d(dtype=wp.int32), n_time: int, n_taxels: int,
                   per_taxel: int, block: int, dst: wp.array(dtype=wp.float32)):
    """dst[m, t, j, k] = src[r, t, b * block + j, k] for (r, b) = index[m] (0 past the last taxel)."""
    m, t, jk = wp.tid()
    j = jk // per_taxel
    k = jk % per_taxel
    n = index[m, 1] * block + j
    v = wp.float32(0.0)
    if n < n_taxels:
        v = src[((index[m, 0] * n_time + t) * n_taxels + n) * per_taxel + k]
    dst[(m * n_time + t) * block * per_taxel + jk] = v


def fields_f32_blocks_to_host(fields: dict[str, wp.array], shapes: dict[str, tuple[int, ...]],
                              block: int | None = None) -> dict:
    """Taxel fields left on the device (float64 Warp arrays, `shapes` (E, T, N, ...) each, one dimension may be -1) ->
    float32 on the host, rounded on the device (numpy's astype(float32), bit for bit; half the bytes of the float64
    fields and no host pass, bench/README.md session 9): a `BlockSparse` of a field's non-zero blocks where at most
    SPARSE_MAX_SHARE of them are non-zero, else the dense array. Blocks, flags, index and dense arrays come back
    through the page-locked buffers of `sensors.warp_setup.to_host` (inside `host_staging`: valid until that site's
    next copy)."""
    from sensors.warp_setup import scratch, to_host
    from simulate.contact.field_blocks import FIELD_BLOCK, SPARSE_MAX_SHARE, BlockSparse

    block = FIELD_BLOCK if block is None else block
    out: dict = {}
    for name, arr in fields.items():
        flat = arr.reshape(-1) if arr.ndim > 1 else arr
        shape = tuple(int(s) for s in shapes[name])
        if -1 in shape:  # one dimension left to the array's size, as in numpy's reshape
            known = int(np.prod([s for s in shape if s != -1], dtype=np.int64))
            shape = tuple(flat.shape[0] // max(1, known) if s == -1 else s for s in shape)
        device = str(arr.device)
        E, T, N = shape[0], shape[1], shape[2]
        K = int(np.prod(shape[3:], dtype=np.int64)) if len(shape) > 3 else 1
        size = max(1, min(block, N))  # a narrow field: one block of its own width
        n_blocks = -(-N // size)
        dst = scratch(f"field {name} f32", flat.shape[0], wp.float32, device)
        wp.launch(_to_f32, dim=flat.shape[0], inputs=[flat, dst], device=device)
        flags = scratch(f"field {name} flags", max(1, E * n_blocks), wp.int32, device)
        flags.zero_()
        if flat.shape[0]:
            bits = wp.array(ptr=dst.ptr, dtype=wp.uint32, shape=dst.shape, device=device)
            wp.launch(_flag_blocks, dim=flat.shape[0], inputs=[bits, T * N * K, K, N, size, n_blocks, flags], device=device)
        hit = np.flatnonzero(to_host(flags, f"field {name} flags")[: E * n_blocks])
        if len(hit) > SPARSE_MAX_SHARE * E * n_blocks:
            out[name] = to_host(dst, f"field {name}").reshape(shape)
            continue
        index = np.stack([hit // n_blocks, hit % n_blocks], axis=1).astype(np.int32)
        M = len(index)
        if M:
            idx = wp.array(index, dtype=wp.int32, device=device)
            comp = scratch(f"field {name} blocks", M * T * size * K, wp.float32, device)
            wp.launch(_gather_blocks, dim=(M, T, size * K), inputs=[dst, idx, T, N, K, size, comp], device=device)
            blocks = to_host(comp, f"field {name} blocks").reshape((M, T, size, *shape[3:]))
        else:
            blocks = np.zeros((0, T, size, *shape[3:]), np.float32)
        out[name] = BlockSparse(blocks, index, shape, size)
    return out


# ---------------------------------------------------------------------------------------------------------------
# press_stroke (ntype): several flat indenters, each force spread uniformly over its footprint (simulate/contact/
# press_stroke.py `_load_batch`, the numpy reference; Johnson, Contact Mechanics, 1985, flat punch on a Winkler
# layer). Frames F = E x T, indenters C; float64 like the reference.


@wp.func
def _box_cover(x: wp.float64, y: wp.float64, hx: wp.float64, hy: wp.float64, ix: int, iy: int,
               x_lo: wp.array(dtype=wp.float64), x_hi: wp.array(dtype=wp.float64), y_lo: wp.array(dtype=wp.float64),
               y_hi: wp.array(dtype=wp.float64), px: wp.float64, py: wp.float64) -> wp.float64:
    """Cell (ix, iy)'s covered fraction: interval_coverage in y times in x (the reference's cy * cx)."""
    zero = wp.float64(0.0)
    cx = wp.max(wp.min(x + hx, x_hi[ix]) - wp.max(x - hx, x_lo[ix]), zero) / px
    cy = wp.max(wp.min(y + hy, y_hi[iy]) - wp.max(y - hy, y_lo[iy]), zero) / py
    return cy * cx


@wp.kernel
def _press_weights(pos: wp.array3d(dtype=wp.float64), hx: wp.float64, hy: wp.float64,
                   x_lo: wp.array(dtype=wp.float64), x_hi: wp.array(dtype=wp.float64), y_lo: wp.array(dtype=wp.float64),
                   y_hi: wp.array(dtype=wp.float64), px: wp.float64, py: wp.float64, w: wp.array2d(dtype=wp.float64)):
    """w[f, c] = indenter c's footprint in cells (sum of its cover over the grid, taxel order)."""
    f, c = wp.tid()
    nx = x_lo.shape[0]
    acc = wp.float64(0.0)
    for iy in range(y_lo.shape[0]):
        for ix in range(nx):
            acc += _box_cover(pos[f, c, 0], pos[f, c, 1], hx, hy, ix, iy, x_lo, x_hi, y_lo, y_hi, px, py)
    w[f, c] = acc


@wp.kernel
def _press_fields(pos: wp.array3d(dtype=wp.float64), fn: wp.array2d(dtype=wp.float64), ft: wp.array3d(dtype=wp.float64),
                  w: wp.array2d(dtype=wp.float64), area: wp.float64, hx: wp.float64, hy: wp.float64,
                  x_lo: wp.array(dtype=wp.float64), x_hi: wp.array(dtype=wp.float64), y_lo: wp.array(dtype=wp.float64),
                  y_hi: wp.array(dtype=wp.float64), px: wp.float64, py: wp.float64,
                  deform: wp.array2d(dtype=wp.float64), pressure: wp.array2d(dtype=wp.float64),
                  shear: wp.array3d(dtype=wp.float64)):
    """deformation = sum_c penetration x cover; pressure, shear = sum_c cover / (area w_c) x force_c (indenters in
    order, as the reference's sums over its indenter axis)."""
    f, n = wp.tid()
    nx = x_lo.shape[0]
    ix = n % nx
    iy = n // nx
    zero = wp.float64(0.0)
    d = zero
    p = zero
    sx = zero
    sy = zero
    for c in range(pos.shape[1]):
        cover = _box_cover(pos[f, c, 0], pos[f, c, 1], hx, hy, ix, iy, x_lo, x_hi, y_lo, y_hi, px, py)
        d += wp.max(-pos[f, c, 2], zero) * cover
        share = zero
        if w[f, c] > zero:
            share = cover / (area * w[f, c])
        p += share * fn[f, c]
        sx += share * ft[f, c, 0]
        sy += share * ft[f, c, 1]
    deform[f, n] = d
    pressure[f, n] = p
    shear[f, n, 0] = sx
    shear[f, n, 1] = sy


def press_fields_warp(cfg: SceneConfig, pos_m: np.ndarray, normal_n: np.ndarray, shear_n: np.ndarray, device: str):
    """press_stroke's taxel fields for box indenters on `device`: pos_m (E, T, C, 3) indenter positions (z < 0:
    into the pad), normal_n (E, T, C), shear_n (E, T, C, 2). Returns (deformation (E T, N), pressure (E T, N),
    shear (E T, N, 2)) as float64 Warp arrays on the device and w (E, T, C) numpy, each indenter's footprint in
    cells (> 0: it found the pad). Against the numpy reference (`press_stroke._load_batch`): the same values
    but for the footprint sum, summed here in taxel order and there pairwise, so the fields agree to ~1e-15
    relative (tests/test_press_stroke_fields.py)."""
    pad, ind = cfg.pad, cfg.indenter
    if ind.shape != "box":
        raise ValueError("press_fields_warp: box indenters only (the sphere's field stays in numpy)")
    E, T, C, _ = pos_m.shape
    F, nx, ny = E * T, pad.taxels_x, pad.taxels_y
    N = nx * ny
    f64 = wp.float64
    px, py = pad.size_x_m / nx, pad.size_y_m / ny
    cx, cy = taxel_centres_1d(pad.size_x_m, nx), taxel_centres_1d(pad.size_y_m, ny)

    def arr(x, shape=None):
        return wp.array(np.ascontiguousarray(x, np.float64).reshape(shape or np.shape(x)), dtype=f64, device=device)

    with wp.ScopedDevice(device):
        edges = [arr(cx - 0.5 * px), arr(cx + 0.5 * px), arr(cy - 0.5 * py), arr(cy + 0.5 * py)]
        geo = [f64(ind.size_x_m / 2), f64(ind.size_y_m / 2)]
        pos = arr(pos_m, (F, C, 3))
        w = wp.empty((F, C), dtype=f64)
        wp.launch(_press_weights, dim=(F, C), inputs=[pos, *geo, *edges, f64(px), f64(py), w])
        deform, pressure, shear = wp.empty((F, N), dtype=f64), wp.empty((F, N), dtype=f64), wp.empty((F, N, 2), dtype=f64)
        wp.launch(_press_fields, dim=(F, N), inputs=[pos, arr(normal_n, (F, C)), arr(shear_n, (F, C, 2)), w,
                                                     f64(taxel_area_m2(cfg)), *geo, *edges, f64(px), f64(py),
                                                     deform, pressure, shear])
        return deform, pressure, shear, w.numpy().reshape(E, T, C)

"""Taxel grid on the pad top, indenter overlap per taxel cell, and the elastic-layer spreading kernel.

Grid: taxel (ix, iy) has its centre at x = -Lx/2 + (ix + 1/2) Lx/nx, y likewise; flat index
n = iy * taxels_x + ix (y slowest, x fastest), so a (..., N) field reshapes to (..., ny, nx).
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from scenes.config import SceneConfig

SPHERE_SUPERSAMPLE = 4  # points per taxel side for the sphere overlap average


def taxel_centres_1d(length_m: float, n: int) -> np.ndarray:
    """(n,) centres of n equal cells spanning [-L/2, L/2] (m)."""
    pitch = length_m / n
    return -0.5 * length_m + (np.arange(n) + 0.5) * pitch


def taxel_xy_m(cfg: SceneConfig) -> np.ndarray:
    """(N, 2) taxel centres (m), flat index n = iy * taxels_x + ix."""
    xs = taxel_centres_1d(cfg.pad.size_x_m, cfg.pad.taxels_x)
    ys = taxel_centres_1d(cfg.pad.size_y_m, cfg.pad.taxels_y)
    gx, gy = np.meshgrid(xs, ys)  # (ny, nx)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def taxel_area_m2(cfg: SceneConfig) -> float:
    return cfg.pad.size_x_m * cfg.pad.size_y_m / cfg.pad.n_taxels


def spread_matrix(length_m: float, n: int, sigma_m: float) -> np.ndarray:
    """(n, n) row-normalised 1-D Gaussian elastic-layer kernel, integrated over each source cell.

    S[i, j] = integral over cell j of g(x_i - x) dx / sum_j(...), g a Gaussian of width sigma_m: a thin
    elastic layer spreads a surface load over ~ its thickness (Johnson, Contact Mechanics, 1985, sect. 5.8);
    the Gaussian is the usual smooth stand-in for that influence function.  # estimate (kernel shape)
    Rows sum to 1, so a uniform field stays uniform (also at the pad edges).
    """
    c = taxel_centres_1d(length_m, n)
    pitch = length_m / n
    lo = (c - 0.5 * pitch)[None, :]
    hi = (c + 0.5 * pitch)[None, :]
    s = ndtr((hi - c[:, None]) / sigma_m) - ndtr((lo - c[:, None]) / sigma_m)
    return s / s.sum(axis=1, keepdims=True)


def interval_coverage(centre_m: np.ndarray, half_m: float, length_m: float, n: int) -> np.ndarray:
    """(..., n) fraction of each cell covered by [centre - half, centre + half]; centre (...)."""
    c = taxel_centres_1d(length_m, n)
    pitch = length_m / n
    lo = np.maximum(centre_m[..., None] - half_m, c - 0.5 * pitch)
    hi = np.minimum(centre_m[..., None] + half_m, c + 0.5 * pitch)
    return np.clip(hi - lo, 0.0, None) / pitch


def sphere_overlap(cfg: SceneConfig, pos_m: np.ndarray, radius_m: float, chunk: int = 4096) -> np.ndarray:
    """(F, ny, nx) cell-averaged overlap depth (m) of a sphere with the undeformed pad top.

    pos_m: (F, 3) position of the sphere's lowest point relative to the pad top (z < 0: penetrating).
    Each cell is supersampled SPHERE_SUPERSAMPLE^2 points.
    """
    pad = cfg.pad
    s = SPHERE_SUPERSAMPLE
    xs = taxel_centres_1d(pad.size_x_m, pad.taxels_x * s)
    ys = taxel_centres_1d(pad.size_y_m, pad.taxels_y * s)
    out = np.zeros((pos_m.shape[0], pad.taxels_y, pad.taxels_x))
    r2 = radius_m * radius_m
    for a in range(0, pos_m.shape[0], chunk):
        p = pos_m[a : a + chunk]
        pen = -p[:, 2]
        dx2 = (xs[None, :] - p[:, 0:1]) ** 2  # (f, nx s)
        dy2 = (ys[None, :] - p[:, 1:2]) ** 2  # (f, ny s)
        rr = dy2[:, :, None] + dx2[:, None, :]  # (f, ny s, nx s)
        h = pen[:, None, None] - radius_m + np.sqrt(np.clip(r2 - rr, 0.0, None))
        h = np.where(rr < r2, np.clip(h, 0.0, None), 0.0)
        f = h.shape[0]
        out[a : a + chunk] = h.reshape(f, pad.taxels_y, s, pad.taxels_x, s).mean(axis=(2, 4))
    return out

"""Reusable matplotlib plots for characterization and experiment reports (numpy + matplotlib, Agg).

Each helper draws on an `ax` you pass (so reports can lay several out) and returns it; `figure()` makes
a figure and `save()` writes a PNG and closes it. Any family, any experiment:

    hysteresis_loop(ax, output, force, drive)    loading / unloading coloured apart (by the drive's slope)
    time_series(axes, t, {label: (values, unit)})  stacked channels against time
    creep_curve(ax, t, values, hold_start_s)       change since the start of a hold, log time
    taxel_map(ax, values, taxel_xy_m, label, unit) a per-taxel field on its grid (errors, sensitivities...)
    unit_dendrogram(ax, curves)                    Ward linkage of units' R(F) curves (velostat's 36 units)
    position_error_map(ax, truth_xy, decoded_xy)   decoded vs true contact position over the film (one force)
    position_error_maps(axes, truth, decoded, F)   the same, one panel per force, one colour range
    episode_overview(view, path)                   force, deformation peak and resistance of one episode
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

LOADING_COLOR = "tab:red"
UNLOADING_COLOR = "tab:blue"


def _plt():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "cairo") and not _interactive():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _interactive() -> bool:
    from simulate.pictures.render import has_display

    return has_display()


def figure(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (5.0, 3.6), **kw):
    """(fig, axes) with axes always a 2-D array."""
    plt = _plt()
    kw.setdefault("squeeze", False)
    return plt.subplots(nrows, ncols, figsize=size, **kw)


def save(fig, path: str | Path, dpi: int = 120) -> Path:
    plt = _plt()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def loading_mask(drive: np.ndarray) -> np.ndarray:
    """(T,) True where the drive (displacement or force command) is rising or at its peak; ties go to the
    previous sample, so holds keep the colour of the ramp before them."""
    d = np.asarray(drive, dtype=np.float64)
    if d.size < 2:
        return np.ones(d.shape, dtype=bool)
    step = np.diff(d, prepend=d[0])
    tol = 1e-9 * max(float(np.ptp(d)), 1e-30)
    sign = np.where(step > tol, 1, np.where(step < -tol, -1, 0))
    # carry the last non-zero slope forward (first samples: rising)
    idx = np.where(sign != 0, np.arange(d.size), 0)
    np.maximum.accumulate(idx, out=idx)
    carried = sign[idx]
    carried[carried == 0] = 1
    return carried > 0


def hysteresis_loop(ax, output: np.ndarray, force: np.ndarray, drive: np.ndarray | None = None, *,
                    xlabel: str = "sensor output", ylabel: str = "force (N)", title: str | None = None,
                    legend: bool = True):
    """Force against sensor output with loading (red) and unloading (blue) segments; `drive` decides
    which is which (default: the force itself). Works for several cycles and minor loops."""
    x = np.asarray(output, dtype=np.float64).ravel()
    y = np.asarray(force, dtype=np.float64).ravel()
    up = loading_mask(y if drive is None else np.asarray(drive).ravel())
    starts = np.flatnonzero(np.diff(up.astype(np.int8))) + 1
    bounds = np.concatenate([[0], starts, [up.size]])
    labelled = set()
    for a, b in zip(bounds[:-1], bounds[1:]):
        loading = bool(up[a])
        color, label = (LOADING_COLOR, "loading") if loading else (UNLOADING_COLOR, "unloading")
        end = min(b + 1, up.size)  # join to the next run's first sample so no gap shows
        ax.plot(x[a:end], y[a:end], color=color, lw=1.4, label=None if label in labelled else label)
        labelled.add(label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if legend:
        ax.legend(loc="best", fontsize=8)
    return ax


def time_series(axes: Sequence, t: np.ndarray, channels: Mapping[str, tuple[np.ndarray, str]], *,
                xlabel: str = "time (s)"):
    """One channel per axis (values (T,) or (T, k) for k lines), labelled with its unit."""
    axes = list(np.ravel(axes))
    if len(axes) < len(channels):
        raise ValueError(f"time_series: {len(channels)} channels but {len(axes)} axes")
    for ax, (label, (vals, unit)) in zip(axes, channels.items()):
        ax.plot(t, np.asarray(vals), lw=1.2)
        ax.set_ylabel(f"{label} ({unit})" if unit and unit != "1" else label)
        ax.grid(alpha=0.3)
    axes[len(channels) - 1].set_xlabel(xlabel)
    return axes


def creep_curve(ax, t: np.ndarray, values: np.ndarray, hold_start_s: float, *, label: str = "",
                unit: str = "", relative: bool = True, log_time: bool = True):
    """Change of `values` since the start of a hold against time since then (log axis: creep and
    relaxation are roughly linear in log t). relative=True plots percent of the value at the hold start."""
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).ravel()
    k0 = int(np.searchsorted(t, hold_start_s))
    if k0 >= t.size - 1:
        raise ValueError(f"creep_curve: hold start {hold_start_s} s is at or after the last sample")
    tt = t[k0 + 1 :] - t[k0]
    dv = v[k0 + 1 :] - v[k0]
    if relative:
        dv = 100.0 * dv / (abs(v[k0]) if v[k0] != 0 else 1.0)
    ax.plot(tt, dv, lw=1.4, label=label or None)
    if log_time:
        ax.set_xscale("log")
    ax.set_xlabel("time since hold start (s)")
    ax.set_ylabel(f"Δ{label or 'value'} (%)" if relative else f"Δ{label or 'value'} ({unit})")
    ax.grid(alpha=0.3, which="both")
    return ax


def taxel_map(ax, values: np.ndarray, taxel_xy_m: np.ndarray, *, label: str = "", unit: str = "",
              cmap: str = "viridis", annotate: bool | None = None, vmin: float | None = None, vmax: float | None = None,
              colorbar: bool = True):
    """A per-taxel value (N,) drawn on its grid (taxel centres (N, 2) in m, regular grid assumed), mm axes,
    colour bar in `unit`. Annotated with the numbers when the grid is small (<= 8 x 8) unless told."""
    xy = np.asarray(taxel_xy_m, dtype=np.float64)
    vals = np.asarray(values, dtype=np.float64).ravel()
    if xy.shape != (vals.size, 2):
        raise ValueError(f"taxel_map: {vals.size} values but taxel_xy_m has shape {xy.shape}")
    xs, ys = np.unique(np.round(xy[:, 0], 12)), np.unique(np.round(xy[:, 1], 12))
    grid = np.full((ys.size, xs.size), np.nan)
    ix = np.searchsorted(xs, np.round(xy[:, 0], 12))
    iy = np.searchsorted(ys, np.round(xy[:, 1], 12))
    grid[iy, ix] = vals
    px = (xs[1] - xs[0]) if xs.size > 1 else 1e-3
    py = (ys[1] - ys[0]) if ys.size > 1 else px
    ext = np.array([xs[0] - px / 2, xs[-1] + px / 2, ys[0] - py / 2, ys[-1] + py / 2]) * 1e3
    im = ax.imshow(grid, origin="lower", extent=ext, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    if colorbar:
        cb = ax.figure.colorbar(im, ax=ax, shrink=0.85)
        cb.set_label(f"{label} ({unit})" if unit else label)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal")
    if annotate is None:
        annotate = grid.size <= 64
    if annotate:
        for (r, c), v in np.ndenumerate(grid):
            if np.isfinite(v):
                ax.text((xs[c]) * 1e3, (ys[r]) * 1e3, f"{v:.3g}", ha="center", va="center", fontsize=7, color="w")
    return ax


def taxel_error_map(ax, predicted: np.ndarray, truth: np.ndarray, taxel_xy_m: np.ndarray, *,
                    unit: str = "", metric: str = "rmse", **kw):
    """Per-taxel error of a (T, N) prediction against the truth: metric 'rmse' | 'mae' | 'max'."""
    e = np.asarray(predicted, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    e = e.reshape(-1, np.asarray(taxel_xy_m).shape[0])
    per = {"rmse": lambda a: np.sqrt(np.mean(a**2, axis=0)), "mae": lambda a: np.mean(np.abs(a), axis=0),
           "max": lambda a: np.max(np.abs(a), axis=0)}
    if metric not in per:
        raise ValueError(f"taxel_error_map: metric must be one of {', '.join(per)} (got '{metric}')")
    return taxel_map(ax, per[metric](e), taxel_xy_m, label=f"{metric.upper()} error", unit=unit, cmap="magma", **kw)


def unit_dendrogram(ax, curves: np.ndarray, *, labels: Sequence[str] | None = None, n_groups: int | None = None,
                    log: bool = False, unit: str = "ohm", Z: np.ndarray | None = None, title: str | None = None):
    """Ward dendrogram (scipy.cluster.hierarchy) of units' response curves, (U, K): one row per unit (e.g.
    the resistance at K force levels). Leaves are labelled 1..U (unit index + 1) unless told; with n_groups
    the branches of the cut that leaves n_groups clusters are coloured apart and the cut is drawn.
    log=True clusters log(curves). Returns (ax, Z, leaves): Z the linkage, leaves the unit order drawn."""
    from scipy.cluster.hierarchy import dendrogram, linkage

    X = np.asarray(curves, dtype=np.float64)
    if X.ndim != 2 or X.shape[0] < 2:
        raise ValueError(f"unit_dendrogram: curves must be (units >= 2, levels); got shape {X.shape}")
    if log:
        X = np.log(X)
    if Z is None:
        Z = linkage(X, method="ward")
    labels = list(labels) if labels is not None else [str(i + 1) for i in range(X.shape[0])]
    h = np.sort(Z[:, 2])
    thr = None
    if n_groups and 1 < n_groups <= X.shape[0]:
        thr = 0.5 * (h[-n_groups] + h[-n_groups + 1]) if n_groups > 1 else None
    d = dendrogram(Z, ax=ax, labels=labels, color_threshold=thr if thr is not None else 0.0,
                   above_threshold_color="0.4", leaf_font_size=7)
    if thr is not None:
        ax.axhline(thr, color="0.3", lw=0.8, ls="--")
    ax.set_xlabel("unit")
    ax.set_ylabel("Ward merge distance" + (" (log R)" if log else f" ({unit})"))
    if title:
        ax.set_title(title)
    return ax, Z, d["leaves"]


def _regular_grid(xy: np.ndarray) -> bool:
    xs, ys = np.unique(np.round(xy[:, 0], 9)), np.unique(np.round(xy[:, 1], 9))
    return xs.size * ys.size == xy.shape[0] and len(np.unique(np.round(xy, 9), axis=0)) == xy.shape[0]


def position_error_map(ax, truth_xy_m: np.ndarray, decoded_xy_m: np.ndarray, *, size_m: tuple[float, float] | None = None,
                       vmax: float | None = None, arrows: float | None = 5.0, title: str | None = None,
                       colorbar: bool = True):
    """Decoded vs true contact position over the film: |decoded - true| (mm) at each true site (P, 2 in m;
    NaN decoded = no reading, left blank), on the site grid when the sites are one, else as squares; arrows
    from each true site toward its decoded position, `arrows` x longer than the error (None: none). The
    film outline is drawn when size_m is given. Returns (ax, error_mm (P,))."""
    t = np.asarray(truth_xy_m, dtype=np.float64).reshape(-1, 2)
    d = np.asarray(decoded_xy_m, dtype=np.float64).reshape(-1, 2)
    if t.shape != d.shape:
        raise ValueError(f"position_error_map: {t.shape[0]} true sites but {d.shape[0]} decoded positions")
    err = np.linalg.norm(d - t, axis=1) * 1e3
    vmax = vmax if vmax is not None else (float(np.nanmax(err)) if np.isfinite(err).any() else 1.0)
    if _regular_grid(t):
        taxel_map(ax, err, t, label="position error", unit="mm", cmap="magma_r", vmin=0.0, vmax=vmax,
                  annotate=False, colorbar=colorbar)
    else:
        sc = ax.scatter(t[:, 0] * 1e3, t[:, 1] * 1e3, c=err, cmap="magma_r", vmin=0.0, vmax=vmax, marker="s", s=60)
        if colorbar:
            ax.figure.colorbar(sc, ax=ax, shrink=0.85).set_label("position error (mm)")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
    if arrows:
        ok = np.isfinite(d).all(axis=1)
        v = (d - t)[ok] * 1e3 * arrows
        ax.quiver(t[ok, 0] * 1e3, t[ok, 1] * 1e3, v[:, 0], v[:, 1], angles="xy", scale_units="xy", scale=1.0,
                  color="tab:cyan", width=0.006)
    if size_m is not None:
        lx, ly = size_m[0] * 1e3 / 2, size_m[1] * 1e3 / 2
        ax.plot([-lx, lx, lx, -lx, -lx], [-ly, -ly, ly, ly, -ly], color="0.3", lw=0.8)
        ax.set_xlim(-lx * 1.05, lx * 1.05)
        ax.set_ylim(-ly * 1.05, ly * 1.05)
    if title is not None:
        ax.set_title(title + (f" (arrows x{arrows:g})" if arrows else ""), fontsize=9)
    return ax, err


def position_error_maps(axes: Sequence, truth_xy_m: np.ndarray, decoded_xy_m: np.ndarray, forces_n: Sequence[float], *,
                        size_m: tuple[float, float] | None = None, arrows: float | None = 5.0, label: str = ""):
    """position_error_map per force level: decoded_xy_m (F, P, 2) at the P sites truth_xy_m (P, 2), one panel
    per force on `axes`, one colour range (0 .. the largest error) so the panels compare.
    Returns (axes, error_mm (F, P))."""
    axes = list(np.ravel(axes))
    d = np.asarray(decoded_xy_m, dtype=np.float64)
    if d.ndim != 3 or d.shape[0] != len(forces_n):
        raise ValueError(f"position_error_maps: decoded_xy_m must be (forces={len(forces_n)}, sites, 2); got {d.shape}")
    if len(axes) < len(forces_n):
        raise ValueError(f"position_error_maps: {len(forces_n)} forces but {len(axes)} axes")
    t = np.asarray(truth_xy_m, dtype=np.float64)
    err = np.linalg.norm(d - t[None], axis=-1) * 1e3
    vmax = float(np.nanmax(err)) if np.isfinite(err).any() else 1.0
    for i, (ax, f) in enumerate(zip(axes, forces_n)):
        position_error_map(ax, t, d[i], size_m=size_m, vmax=vmax, arrows=arrows,
                           title=f"{label + ' ' if label else ''}{f:g} N: mean {np.nanmean(err[i]):.2f} mm",
                           colorbar=(i == len(forces_n) - 1))
    return axes, err


def episode_overview(view, path: str | Path, field: str = "deformation") -> Path:
    """One episode at a glance: drive-coloured force-resistance loop, force/peak field/resistance against
    time, and the field's per-taxel peak over the episode on the taxel grid."""
    from simulate.pictures.fields import FIELDS

    spec = FIELDS[field]
    t = view.time_s
    fig, axes = figure(3, 2, size=(10.0, 7.0), gridspec_kw={"width_ratios": [1.3, 1.0]})
    chans = {"force": (view.force_n, "N"),
             f"peak {spec.label}": (np.nanmax(view.fields[field], axis=1) * spec.scale, spec.unit)}
    res = view.fields.get("resistance")
    if res is not None:
        chans["resistance"] = (res.mean(axis=1), "ohm")
    time_series(axes[: len(chans), 0], t, chans)
    for ax in axes[len(chans):, 0]:
        ax.set_visible(False)
    if res is not None:
        drive = -view.position_m[:, 2] if np.all(np.isfinite(view.position_m[:, 2])) else None
        hysteresis_loop(axes[0, 1], res.mean(axis=1), view.force_n, drive, xlabel="resistance (ohm)",
                        title="force-resistance loop")
    else:
        axes[0, 1].set_visible(False)
    xy = np.asarray(view.sensor_attrs.get("taxel_xy_m"))
    gs = axes[1, 1].get_gridspec()
    axes[1, 1].remove()
    axes[2, 1].remove()
    big = fig.add_subplot(gs[1:, 1])
    taxel_map(big, np.nanmax(view.fields[field], axis=0) * spec.scale, xy, label=f"peak {spec.label}",
              unit=spec.unit, cmap=spec.cmap)
    fig.suptitle(f"{view.family} · {view.ep_id}")
    return save(fig, path)

"""Reusable matplotlib plots for characterization and experiment reports (numpy + matplotlib, Agg).

Each helper draws on an `ax` you pass (so reports can lay several out) and returns it; `figure()` makes
a figure and `save()` writes a PNG and closes it. Any family, any experiment:

    hysteresis_loop(ax, output, force, drive)    loading / unloading coloured apart (by the drive's slope)
    time_series(axes, t, {label: (values, unit)})  stacked channels against time
    creep_curve(ax, t, values, hold_start_s)       change since the start of a hold, log time
    taxel_map(ax, values, taxel_xy_m, label, unit) a per-taxel field on its grid (errors, sensitivities...)
    episode_overview(view, path)                   force, deformation peak and resistance of one episode
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

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
    from simulate.render import has_display

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
              cmap: str = "viridis", annotate: bool | None = None, vmin: float | None = None, vmax: float | None = None):
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


def episode_overview(view, path: str | Path, field: str = "deformation") -> Path:
    """One episode at a glance: drive-coloured force-resistance loop, force/peak field/resistance against
    time, and the field's per-taxel peak over the episode on the taxel grid."""
    from simulate.fields import FIELDS

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

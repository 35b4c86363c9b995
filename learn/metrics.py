"""Error metrics of the four papers, on numpy arrays (reference first, estimate second).

  mae, rmse, r2                cnt_pdms eqs. 11-13
  mse, pearson_r               fabric (Appendix Table 2: MSE and the correlation coefficient R)
  mean_relative_error          ntype eq. 14: mean |(F' - F) / F| (a fraction; x100 for %)
  hysteresis_error_fso         cnt_pdms sect. 3.1 via sensors.analysis: max force gap between the
                               loading and unloading branches at equal output, % of full-scale force
  cycle_slices, loop_hysteresis  cut a sinusoidal episode into cycles and apply it per cycle
"""

from __future__ import annotations

import numpy as np

from sensors.analysis import hysteresis_error_fso as _hyst

__all__ = [
    "cycle_slices",
    "hysteresis_error_fso",
    "loop_hysteresis",
    "mae",
    "mean_relative_error",
    "mse",
    "pearson_r",
    "r2",
    "regression_metrics",
    "rmse",
]


def _pair(ref, est) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(ref, dtype=np.float64).ravel()
    b = np.asarray(est, dtype=np.float64).ravel()
    if a.shape != b.shape:
        raise ValueError(f"reference and estimate differ in size: {a.shape} vs {b.shape}")
    if a.size == 0:
        raise ValueError("empty arrays")
    return a, b


def mae(ref, est) -> float:
    a, b = _pair(ref, est)
    return float(np.mean(np.abs(a - b)))


def mse(ref, est) -> float:
    a, b = _pair(ref, est)
    return float(np.mean((a - b) ** 2))


def rmse(ref, est) -> float:
    return float(np.sqrt(mse(ref, est)))


def r2(ref, est) -> float:
    """1 - SS_res / SS_tot about the reference mean (can be negative; nan for a constant reference)."""
    a, b = _pair(ref, est)
    ss_tot = float(np.sum((a - a.mean()) ** 2))
    if ss_tot == 0.0:
        return float("nan")
    return float(1.0 - np.sum((a - b) ** 2) / ss_tot)


def pearson_r(ref, est) -> float:
    """Correlation coefficient R between reference and estimate (nan if either is constant)."""
    a, b = _pair(ref, est)
    da, db = a - a.mean(), b - b.mean()
    den = float(np.sqrt(np.sum(da * da) * np.sum(db * db)))
    return float(np.sum(da * db) / den) if den > 0 else float("nan")


def mean_relative_error(ref, est, min_abs_ref: float = 0.0) -> float:
    """ntype eq. 14: mean over samples of |(F' - F) / F|. Samples with |F| <= min_abs_ref are left out
    (the relative error of a zero force is undefined); nan when none is left."""
    a, b = _pair(ref, est)
    keep = np.abs(a) > min_abs_ref
    if not keep.any():
        return float("nan")
    return float(np.mean(np.abs((b[keep] - a[keep]) / a[keep])))


def hysteresis_error_fso(force_ref, output, drive, n_grid: int = 200) -> float:
    """cnt_pdms definition on one cycle (rest -> peak -> rest of ``drive``): max |F_load - F_unload|
    at equal ``output`` over max force, in % (see sensors.analysis.hysteresis_error_fso).

    For a raw sensor ``output`` is its reading (resistance); after compensation it is the estimated
    force, so a perfect compensator (output == force) scores 0."""
    return _hyst(np.asarray(force_ref, float).ravel(), np.asarray(output, float).ravel(),
                 np.asarray(drive, float).ravel(), n_grid)


def cycle_slices(drive, rel_threshold: float = 1e-3, min_len: int = 5) -> list[slice]:
    """Cycles of a drive that rests at zero between presses: each run where drive > rel_threshold x max,
    widened by one sample on each side (so a cycle starts and ends at rest)."""
    d = np.asarray(drive, dtype=np.float64).ravel()
    if d.size == 0 or d.max() <= 0:
        return []
    on = d > rel_threshold * d.max()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(np.int8), [0]])))
    out = []
    for s, e in zip(edges[::2], edges[1::2]):
        s, e = max(0, s - 1), min(len(d), e + 1)
        if e - s >= min_len:
            out.append(slice(int(s), int(e)))
    return out


def loop_hysteresis(force_ref, output, drive, skip_first: bool = False) -> list[float]:
    """Hysteresis error % FSO of each cycle of an episode (nan where the branches do not overlap)."""
    f = np.asarray(force_ref, float).ravel()
    y = np.asarray(output, float).ravel()
    d = np.asarray(drive, float).ravel()
    cyc = cycle_slices(d)
    if skip_first:
        cyc = cyc[1:]
    return [hysteresis_error_fso(f[c], y[c], d[c]) for c in cyc]


def regression_metrics(ref, est) -> dict[str, float]:
    """The point metrics of all four papers at once."""
    return {
        "mae": mae(ref, est), "rmse": rmse(ref, est), "r2": r2(ref, est),
        "mse": mse(ref, est), "r": pearson_r(ref, est),
    }

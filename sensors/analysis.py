"""Loop analysis of one force/sensor-output cycle: hysteresis error (% FSO), loop area, phase lag.

Hysteresis error follows cnt_pdms sect. 3.1: the maximum gap in force between the loading and the
unloading branch at equal sensor output, over the full-scale (maximum applied) force.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LoopMetrics:
    hysteresis_fso_pct: float  # max |F_load(y) - F_unload(y)| / F_max x 100
    loop_area_norm: float  # area of the loop in the (output / output span, F / F_max) plane, 0..1
    phase_lag_deg: float  # lag of the sensor output behind the force at the drive frequency
    force_max_n: float


def split_branches(drive: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays of the loading (drive rising to its peak) and unloading (after the peak) parts of one cycle."""
    k = int(np.argmax(drive))
    return np.arange(0, k + 1), np.arange(k, len(drive))


def hysteresis_error_fso(force_n: np.ndarray, output: np.ndarray, drive: np.ndarray, n_grid: int = 200) -> float:
    """Max force gap between branches at equal output, % of full-scale force (one cycle: rest -> peak -> rest)."""
    load, unload = split_branches(drive)
    yl, fl = output[load], force_n[load]
    yu, fu = output[unload], force_n[unload]
    lo = max(yl.min(), yu.min())
    hi = min(yl.max(), yu.max())
    if hi <= lo:
        return float("nan")
    grid = np.linspace(lo, hi, n_grid)
    ol, ou = np.argsort(yl), np.argsort(yu)
    gap = np.abs(np.interp(grid, yl[ol], fl[ol]) - np.interp(grid, yu[ou], fu[ou]))
    return float(100.0 * gap.max() / max(float(force_n.max()), 1e-12))


def loop_area(force_n: np.ndarray, output: np.ndarray) -> float:
    """Shoelace area of the closed (output, force) loop, both normalised to their spans."""
    f = force_n / max(float(np.ptp(force_n)), 1e-12)
    y = (output - output.min()) / max(float(np.ptp(output)), 1e-12)
    return float(0.5 * abs(np.dot(y, np.roll(f, -1)) - np.dot(f, np.roll(y, -1))))


def phase_lag_deg(force_n: np.ndarray, output: np.ndarray, frequency_hz: float, sample_rate_hz: float) -> float:
    """Phase of the output's fundamental behind the force's, in degrees (sign chosen so that an output
    whose magnitude of change lags the force is positive, whatever the sign of the sensitivity)."""
    t = np.arange(len(force_n)) / sample_rate_hz
    ph = np.exp(-2j * np.pi * frequency_hz * t)
    pf = np.angle(np.sum((force_n - force_n.mean()) * ph))
    slope = np.sign(np.polyfit(force_n, output, 1)[0]) or 1.0
    py = np.angle(np.sum(slope * (output - output.mean()) * ph))
    return float(np.degrees((pf - py + np.pi) % (2 * np.pi) - np.pi))


def loop_metrics(force_n, output, drive, frequency_hz: float, sample_rate_hz: float) -> LoopMetrics:
    return LoopMetrics(
        hysteresis_fso_pct=hysteresis_error_fso(force_n, output, drive),
        loop_area_norm=loop_area(force_n, output),
        phase_lag_deg=phase_lag_deg(force_n, output, frequency_hz, sample_rate_hz),
        force_max_n=float(force_n.max()),
    )


def branch_gaps(force_n: np.ndarray, output: np.ndarray, drive: np.ndarray, n_grid: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """(output grid over the range both branches share, |F_load - F_unload| there, % of full-scale force)."""
    load, unload = split_branches(drive)
    yl, fl = output[load], force_n[load]
    yu, fu = output[unload], force_n[unload]
    lo, hi = max(yl.min(), yu.min()), min(yl.max(), yu.max())
    if hi <= lo:
        return np.empty(0), np.empty(0)
    grid = np.linspace(lo, hi, n_grid)
    ol, ou = np.argsort(yl), np.argsort(yu)
    gap = np.abs(np.interp(grid, yl[ol], fl[ol]) - np.interp(grid, yu[ou], fu[ou]))
    return grid, 100.0 * gap / max(float(force_n.max()), 1e-12)


def third_gaps_fso(force_n: np.ndarray, output: np.ndarray, drive: np.ndarray) -> tuple[float, float]:
    """Max force gap (% FSO) in the lower and in the upper third of the loop's output span: a symmetric
    (elliptic) loop gives equal values, an asymmetric one does not."""
    grid, gap = branch_gaps(force_n, output, drive)
    if not len(grid):
        return float("nan"), float("nan")
    lo, hi = float(output.min()), float(output.max())
    third = (hi - lo) / 3.0
    low, up = gap[grid <= lo + third], gap[grid >= hi - third]
    return (float(low.max()) if len(low) else float("nan")), (float(up.max()) if len(up) else float("nan"))


def output_gap_span_pct(force_n: np.ndarray, output: np.ndarray, drive: np.ndarray, n_grid: int = 200) -> float:
    """The other common definition: max output gap between the branches at equal force, % of the output span."""
    load, unload = split_branches(drive)
    fl, yl = force_n[load], output[load]
    fu, yu = force_n[unload], output[unload]
    lo, hi = max(fl.min(), fu.min()), min(fl.max(), fu.max())
    if hi <= lo:
        return float("nan")
    grid = np.linspace(lo, hi, n_grid)
    ol, ou = np.argsort(fl), np.argsort(fu)
    gap = np.abs(np.interp(grid, fl[ol], yl[ol]) - np.interp(grid, fu[ou], yu[ou]))
    return float(100.0 * gap.max() / max(float(np.ptp(output)), 1e-30))

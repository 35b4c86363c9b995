"""What a calibration procedure returns: the targets it fits, the values it reached, the fitted fields.

A family's calibration (e.g. sensors/fabric/calibrate.py) fits physical parameters of a preset to
stated targets (a paper's curves or figures) and returns a CalibrationResult; `piezotwin calibrate
FAMILY` prints targets beside results and, with --write, writes the fitted fields into the preset.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class TargetRow:
    """One target of a calibration: what it is, the target (or band), what the fitted model gives."""

    name: str
    target: str  # e.g. "24.2", "8-17"
    result: float
    unit: str = ""
    met: bool | None = None  # None where no pass/fail band is stated


@dataclass
class CalibrationResult:
    """Targets vs results, and the preset edits that carry the fit: {preset file: {dotted field: value}}."""

    family: str
    rows: list[TargetRow] = field(default_factory=list)
    preset_fields: dict[str, dict[str, float]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def root_in_bracket(f: Callable[[float], float], lo: float, hi: float, xtol: float) -> float:
    """Where a rising f crosses zero in [lo, hi] (Brent's method), or the bracket's end when f has one sign there:
    the fitted parameter of a calibration whose target figure grows with it."""
    from scipy.optimize import brentq

    if f(lo) >= 0:
        return lo
    if f(hi) <= 0:
        return hi
    return float(brentq(f, lo, hi, xtol=xtol))


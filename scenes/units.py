"""Quantities with units for config values: "5 mm" -> 0.005 for a field named `*_m`.

Field names carry their SI unit as a suffix (`thickness_m`, `youngs_modulus_pa`); a value may be a
plain number (already SI) or a string with a unit that is converted to SI. A unit of the wrong
dimension is an error that names the allowed units.
"""

from __future__ import annotations

import re

# suffix -> {unit spelling: factor to SI}
UNITS_BY_SUFFIX: dict[str, dict[str, float]] = {
    "_m": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6},
    "_m2": {"m2": 1.0, "cm2": 1e-4, "mm2": 1e-6},
    "_pa": {"pa": 1.0, "kpa": 1e3, "mpa": 1e6, "gpa": 1e9},
    "_s": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0},
    "_hz": {"hz": 1.0, "khz": 1e3},
    "_n": {"n": 1.0, "mn": 1e-3, "kn": 1e3},
    "_kg": {"kg": 1.0, "g": 1e-3},
    "_ohm": {"ohm": 1.0, "kohm": 1e3, "mohm": 1e6},
    "_v": {"v": 1.0, "mv": 1e-3, "uv": 1e-6},
    "_s_per_m": {"s/m": 1.0, "s_per_m": 1.0},
    "_m_per_s": {"m/s": 1.0, "mm/s": 1e-3, "mm/min": 1e-3 / 60.0},
    "_n_per_m": {"n/m": 1.0, "n/mm": 1e3},
}

_QTY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-zµ/0-9_]*)\s*$")


def unit_suffix(field_name: str) -> str | None:
    """The SI-unit suffix of a field name, longest match first, or None for dimensionless fields."""
    for suffix in sorted(UNITS_BY_SUFFIX, key=len, reverse=True):
        if field_name.endswith(suffix):
            return suffix
    return None


def parse_quantity(field_name: str, value: object) -> object:
    """Convert "12 mm" to SI for a field whose name ends in a unit suffix; other values pass through.

    Raises ValueError naming the field and the allowed units when the unit does not fit.
    """
    if not isinstance(value, str):
        return value
    suffix = unit_suffix(field_name)
    m = _QTY.match(value)
    if m is None:
        return value  # let pydantic report the type error
    number, unit = float(m.group(1)), m.group(2).lower()
    if suffix is None:
        if unit:
            raise ValueError(f"'{field_name}' is dimensionless; got unit '{m.group(2)}'")
        return number
    table = UNITS_BY_SUFFIX[suffix]
    if not unit:
        return number
    if unit not in table:
        allowed = ", ".join(sorted(set(table)))
        raise ValueError(
            f"'{field_name}' takes a value in {suffix[1:]} units; got unit '{m.group(2)}' (allowed: {allowed})"
        )
    return number * table[unit]

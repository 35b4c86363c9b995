"""Shared pieces of every scene config: the strict base model and the constrained float types.

Kept apart from scenes/config.py so that the family configs (fabric, velostat, ntype) and the scene
that gathers them import one way only.

Every float is finite (inf and nan are errors) and every physical field has a plausible upper bound,
written in its type on the field's line (`Pos(0.1)` = 0 < x <= 0.1): far beyond any sensor of the four
papers, close enough that a typo (1e30, a value in the wrong unit) fails validation instead of running
on into NaN, a hung simulation or a MuJoCo error log.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from scenes.units import parse_quantity

PositiveFloat = Annotated[float, Field(gt=0)]
NonNegFloat = Annotated[float, Field(ge=0)]
Fraction = Annotated[float, Field(ge=0, le=1)]


def Pos(hi: float) -> Any:
    """A float with 0 < x <= hi."""
    return Annotated[float, Field(gt=0, le=hi)]


def NonNeg(hi: float) -> Any:
    """A float with 0 <= x <= hi."""
    return Annotated[float, Field(ge=0, le=hi)]


def Between(lo: float, hi: float) -> Any:
    """A float with lo <= x <= hi."""
    return Annotated[float, Field(ge=lo, le=hi)]


class Strict(BaseModel):
    """Base: unknown fields are errors, inf and nan are errors, values with units are converted to SI
    before validation."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _units(cls, data: object) -> object:
        if isinstance(data, dict):
            return {k: parse_quantity(k, v) if isinstance(k, str) else v for k, v in data.items()}
        return data

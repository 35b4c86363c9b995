"""Shared pieces of every scene config: the strict base model and the constrained float types.

Kept apart from scenes/config.py so that the family configs (fabric, velostat, ntype) and the scene
that gathers them import one way only.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

from scenes.units import parse_quantity

PositiveFloat = Annotated[float, Field(gt=0)]
NonNegFloat = Annotated[float, Field(ge=0)]
Fraction = Annotated[float, Field(ge=0, le=1)]


class Strict(BaseModel):
    """Base: unknown fields are errors, values with units are converted to SI before validation."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)

    @model_validator(mode="before")
    @classmethod
    def _units(cls, data: object) -> object:
        if isinstance(data, dict):
            return {k: parse_quantity(k, v) if isinstance(k, str) else v for k, v in data.items()}
        return data

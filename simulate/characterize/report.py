"""A characterization report: a table of ours-beside-the-paper rows, notes, and an optional plot.

Every family's `characterize` returns one; the CLI prints it and writes the plot."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Report:
    title: str
    columns: list[str]
    rows: list[list[str]]
    notes: list[str] = field(default_factory=list)
    metrics: dict[str, Any] = field(default_factory=dict)  # the same numbers, machine-readable
    plot: Callable[[str], None] | None = None  # writes a PNG to the given path


def fmt(x: float | None, digits: int = 1) -> str:
    return "-" if x is None else f"{x:.{digits}f}"

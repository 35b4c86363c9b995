"""`piezotwin calibrate FAMILY`: fit a family's physical parameters to its stated targets, print targets
beside results, and with --write put the fitted values into the preset(s)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from piezotwin.common import app, console, fail

# family -> "module:function" returning a sensors.calibration.CalibrationResult; each family adds one line
CALIBRATIONS: dict[str, str] = {
    "fabric": "sensors.fabric.calibrate:run",
    "cnt_pdms": "simulate.characterize.cnt_pdms:calibrate",
    "velostat": "simulate.characterize.velostat:calibrate",
}


def write_preset_fields(path: Path, fields: dict[str, float]) -> None:
    """Set dotted fields (e.g. sensor.material.gamma) in a preset YAML, keeping its comments and layout.

    A field is written on the line holding its last key under the right parents (indentation); a flow
    mapping line (``stack: {a: 1, b: 2}``) has the key replaced inside it."""
    lines = path.read_text().splitlines()
    for dotted, value in fields.items():
        keys = dotted.split(".")
        val = f"{value:.6g}" if isinstance(value, float) else str(value)
        start, indent = 0, -1
        for depth, key in enumerate(keys):
            found = None
            for i in range(start, len(lines)):
                ln = lines[i]
                stripped = ln.lstrip()
                ind = len(ln) - len(stripped)
                if stripped and not stripped.startswith("#") and ind <= indent and i > start:
                    break
                if ind > indent and re.match(rf"{re.escape(key)}\s*:", stripped):
                    found = i
                    break
                flow = re.search(rf"([{{,]\s*){re.escape(key)}\s*:\s*[^,}}]+", ln)
                if flow and depth == len(keys) - 1 and (ind > indent or i == start):
                    lines[i] = ln[: flow.start()] + f"{flow.group(1)}{key}: {val}" + ln[flow.end():]
                    found = -1
                    break
            if found is None:
                raise KeyError(f"{path.name}: no field {dotted} to write (add it to the preset first)")
            if found == -1:
                break
            if depth == len(keys) - 1:
                ln = lines[found]
                m = re.match(rf"(\s*{re.escape(key)}\s*:\s*)([^#]*?)(\s*#.*)?$", ln)
                lines[found] = m.group(1) + val + (m.group(3) or "")
            start, indent = found, len(lines[found]) - len(lines[found].lstrip())
    path.write_text("\n".join(lines) + "\n")


@app.command()
def calibrate(
    family: Annotated[str, typer.Argument(help="Sensor family whose calibration to run.")],
    write: Annotated[bool, typer.Option("--write", help="Write the fitted values into the preset(s).")] = False,
) -> None:
    """Fit a family's physical parameters to its paper's targets; print targets beside results."""
    if family not in CALIBRATIONS:
        fail(f"no calibration for family '{family}' (allowed: {', '.join(sorted(CALIBRATIONS))})")
    module, fn = CALIBRATIONS[family].split(":")
    with console.status(f"calibrating {family} ..."):
        res = getattr(importlib.import_module(module), fn)()
    table = Table(title=f"calibration of {family}: targets and results")
    for col in ("target", "wanted", "fitted", "unit", "met"):
        table.add_column(col, overflow="fold")
    for r in res.rows:
        table.add_row(r.name, r.target, f"{r.result:.4g}", r.unit, {None: "", True: "yes", False: "NO"}[r.met])
    console.print(table)
    for note in res.notes:
        console.print(f"- {note}")
    for path, fields in res.preset_fields.items():
        if write:
            write_preset_fields(Path(path), fields)
            console.print(f"wrote {len(fields)} fields into {path}")
        else:
            console.print(f"{Path(path).name}: " + ", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in fields.items()) + "  (--write to save)")

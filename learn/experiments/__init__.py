"""Paper experiments, by paper key. Each module has ``run(out_dir, mode=..., ...) -> metrics dict``
and ``MODES`` (e.g. "quick", "full"); ``piezotwin experiment <key>`` calls it. A new family adds its
module name here."""

from __future__ import annotations

import importlib
from types import ModuleType

EXPERIMENTS: dict[str, str] = {
    "cnt_pdms": "learn.experiments.cnt_pdms",
    "velostat": "learn.experiments.velostat",
    "fabric": "learn.experiments.fabric",
    "ntype": "learn.experiments.ntype",
}


def get_experiment(key: str) -> ModuleType:
    if key not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {key!r}; known: {', '.join(sorted(EXPERIMENTS))}")
    return importlib.import_module(EXPERIMENTS[key])

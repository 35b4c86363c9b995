"""Characterization of each family's preset beside its paper: one module per family, a report format, a dispatcher."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from scenes import SceneConfig
    from simulate.characterize.report import Report

# family -> "module:function" returning a Report; each family adds one line
CHARACTERIZERS: dict[str, str] = {
    "cnt_pdms": "simulate.characterize.cnt_pdms:characterize_cnt_pdms",
    "fabric": "simulate.characterize.fabric:characterize_fabric",
    "ntype": "simulate.characterize.ntype:characterize_ntype",
    "velostat": "simulate.characterize.velostat:characterize_velostat",
}


def characterize(cfg: SceneConfig, backend: str = "warp", device: str = "cpu") -> Report:
    import importlib

    fam = cfg.sensor.family
    if fam not in CHARACTERIZERS:
        raise ValueError(f"no characterization for family {fam!r} (allowed: {', '.join(sorted(CHARACTERIZERS))})")
    module, fn = CHARACTERIZERS[fam].split(":")
    return getattr(importlib.import_module(module), fn)(cfg, backend=backend, device=device)

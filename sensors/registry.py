"""Sensor family -> model class. Each family adds one line; the classes are imported lazily."""

from __future__ import annotations

import importlib

from scenes import SceneConfig
from sensors.base import SensorModel

FAMILIES: dict[str, str] = {
    "cnt_pdms": "sensors.cnt_pdms.model:CntPdmsSensor",
    "fabric": "sensors.fabric.model:FabricSensor",
    "ntype": "sensors.ntype.model:NtypeSensor",
    "velostat": "sensors.velostat.model:VelostatSensor",
}


def sensor_class(family: str) -> type:
    """The model class of a family (its class attribute `outputs` names the channels it produces)."""
    if family not in FAMILIES:
        raise ValueError(f"sensor.family {family!r} has no model (allowed: {', '.join(sorted(FAMILIES))})")
    module, cls = FAMILIES[family].split(":")
    return getattr(importlib.import_module(module), cls)


def make_sensor(cfg: SceneConfig, backend: str = "warp", device: str = "cpu") -> SensorModel:
    return sensor_class(cfg.sensor.family)(cfg, backend=backend, device=device)

"""Checkpoints: a folder with ``config.json`` (what the model is and how to feed it) and
``model.safetensors`` (its tensors). Nothing is ever unpickled: the model is rebuilt from its registry
name and hyper-parameters, and its tensors are read with safetensors.

config.json:
  format, format_version, model_class (registry kind), python_class (informational),
  hyper_parameters, n_inputs, n_outputs, inputs / targets ([{name, units}]),
  normalization {x: {mean, std}, y: {mean, std}} (z-score, training set), context (samples of history),
  dataset (manifest sha256, dataset_sha256, config_sha256, path), seed, version (piezotwin + git),
  created_utc, training (history summary), extra (free-form, e.g. experiment metrics).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from safetensors.numpy import load_file, save_file

from learn.models.base import Compensator, make_model
from learn.normalize import ZScore

__all__ = ["CHECKPOINT_FORMAT", "CHECKPOINT_VERSION", "load_checkpoint", "read_config", "save_checkpoint"]

CHECKPOINT_FORMAT = "piezotwin-checkpoint"
CHECKPOINT_VERSION = 1
CONFIG_NAME = "config.json"
TENSORS_NAME = "model.safetensors"


def _version() -> dict[str, str]:
    try:
        from sensors.data.recording import generator_info

        return dict(generator_info())
    except Exception:  # noqa: BLE001
        return {"package": "piezotwin"}


def save_checkpoint(
    comp: Compensator,
    directory: str | os.PathLike,
    *,
    dataset: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
) -> Path:
    """Write the checkpoint folder (created; files replaced atomically); returns it."""
    comp._check_fitted()
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    tensors = {k: np.ascontiguousarray(v) for k, v in comp.state_tensors().items()}
    hist = {k: v for k, v in comp.history.items() if k not in ("train_loss", "valid_loss")}
    cfg = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "model_class": comp.kind,
        "python_class": f"{type(comp).__module__}.{type(comp).__qualname__}",
        "hyper_parameters": comp.hparams,
        "context": comp.context,
        "n_inputs": comp.n_in,
        "n_outputs": comp.n_out,
        "inputs": [{"name": n, "units": comp.units.get(n, "")} for n in comp.inputs],
        "targets": [{"name": n, "units": comp.units.get(n, "")} for n in comp.targets],
        "normalization": {"method": "z-score", "x": comp.x_norm.to_json(), "y": comp.y_norm.to_json()},
        "dataset": dataset or {},
        "seed": comp.seed,
        "version": _version(),
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
        "training": hist,
        "tensors": {k: {"shape": list(v.shape), "dtype": str(v.dtype)} for k, v in tensors.items()},
        "extra": extra or {},
    }
    tmp_t, tmp_c = d / (TENSORS_NAME + ".tmp"), d / (CONFIG_NAME + ".tmp")
    save_file(tensors, str(tmp_t), metadata={"format": CHECKPOINT_FORMAT, "model_class": comp.kind})
    tmp_c.write_text(json.dumps(cfg, indent=2, default=_json_default))
    os.replace(tmp_t, d / TENSORS_NAME)
    os.replace(tmp_c, d / CONFIG_NAME)
    return d


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o)}")


def read_config(directory: str | os.PathLike) -> dict[str, Any]:
    cfg = json.loads((Path(directory) / CONFIG_NAME).read_text())
    if cfg.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{directory}: not a piezotwin checkpoint (format={cfg.get('format')!r})")
    if int(cfg.get("format_version", 0)) > CHECKPOINT_VERSION:
        raise ValueError(f"{directory}: checkpoint format_version {cfg['format_version']} is newer than this code ({CHECKPOINT_VERSION})")
    return cfg


def load_checkpoint(directory: str | os.PathLike) -> Compensator:
    """Rebuild the compensator: registry kind + hyper-parameters, norms and channels from config.json,
    tensors from model.safetensors."""
    cfg = read_config(directory)
    comp = make_model(cfg["model_class"], **cfg["hyper_parameters"])
    comp.n_in, comp.n_out = int(cfg["n_inputs"]), int(cfg["n_outputs"])
    comp.inputs = [c["name"] for c in cfg["inputs"]]
    comp.targets = [c["name"] for c in cfg["targets"]]
    comp.units = {c["name"]: c["units"] for c in cfg["inputs"] + cfg["targets"]}
    comp.x_norm = ZScore.from_json(cfg["normalization"]["x"])
    comp.y_norm = ZScore.from_json(cfg["normalization"]["y"])
    comp.seed = int(cfg.get("seed", 0))
    comp.history = dict(cfg.get("training", {}))
    comp.load_state_tensors(load_file(str(Path(directory) / TENSORS_NAME)))
    return comp

"""Load a scene: a preset name or a YAML file, plus `key=value` overrides, validated into SceneConfig.

Errors come out as ConfigError with one line that names the field and what is allowed.
"""

from __future__ import annotations

import difflib
import json
import re
from pathlib import Path
from typing import Any

import yaml
import typing

from pydantic import BaseModel, ValidationError

from scenes.config import SceneConfig

PRESET_DIR = Path(__file__).parent / "presets"


class ConfigError(ValueError):
    """A scene config that cannot be used; str() is one line naming the field."""


def list_presets() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def _read_source(source: str | Path) -> dict[str, Any]:
    path = Path(source)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError(f"scene file '{source}' does not exist")
        text = path.read_text()
    else:
        preset = PRESET_DIR / f"{source}.yaml"
        if not preset.is_file():
            raise ConfigError(f"unknown preset '{source}' (allowed: {', '.join(list_presets())}, or a .yaml file)")
        text = preset.read_text()
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"scene file '{source}' is not valid YAML: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"scene file '{source}' must hold a mapping at the top level")
    return data


def _fields_at(path: list[str]) -> list[str]:
    """Allowed field names at a dotted path inside SceneConfig (for error messages)."""
    model: type[BaseModel] | None = SceneConfig
    for part in path:
        if model is None or part not in model.model_fields:
            return []
        ann = model.model_fields[part].annotation
        members = [a for a in _union_members(ann) if isinstance(a, type) and issubclass(a, BaseModel)]
        if members and not (isinstance(ann, type) and issubclass(ann, BaseModel)):  # a union (sensor families)
            fields = sorted({f for m in members for f in m.model_fields})
            rest = path[path.index(part) + 1:]
            subs = [_fields_in(m, rest) for m in members]
            return sorted({f for s in subs for f in s}) if rest else fields
        model = ann if isinstance(ann, type) and issubclass(ann, BaseModel) else None
    return sorted(model.model_fields) if model is not None else []


def _fields_in(model: type[BaseModel], path: list[str]) -> list[str]:
    for part in path:
        if part not in model.model_fields:
            return []
        ann = model.model_fields[part].annotation
        if not (isinstance(ann, type) and issubclass(ann, BaseModel)):
            return []
        model = ann
    return sorted(model.model_fields)


def _union_members(ann: object) -> list:
    """Model classes of a (possibly Annotated / tagged) union annotation; [] for anything else."""
    if typing.get_origin(ann) is typing.Annotated:
        ann = typing.get_args(ann)[0]
    out = []
    for a in typing.get_args(ann):
        if typing.get_origin(a) is typing.Annotated:
            a = typing.get_args(a)[0]
        out.append(a)
    return out


def _tags(loc: list[str]) -> list[str]:
    """Drop the discriminator tag pydantic puts in the location of a union member ('sensor.velostat.film')."""
    if len(loc) > 1 and loc[0] == "sensor":
        from scenes.config import SensorConfig

        tags = {typing.get_args(m.model_fields["family"].annotation)[0] for m in _union_members(SensorConfig)}
        if loc[1] in tags:
            return [loc[0], *loc[2:]]
    return loc


def apply_overrides(data: dict[str, Any], overrides: list[str] | None) -> dict[str, Any]:
    """Apply `a.b.c=value` overrides (value parsed as YAML: numbers, lists, "5 mm")."""
    for item in overrides or []:
        if "=" not in item:
            raise ConfigError(f"override '{item}' must look like key.path=value")
        key, raw = item.split("=", 1)
        parts = key.strip().split(".")
        node = data
        for i, part in enumerate(parts[:-1]):
            allowed = _fields_at(parts[:i])
            if allowed and part not in allowed:
                raise ConfigError(_unknown(".".join(parts[: i + 1]), part, allowed))
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"override '{key}': '{'.'.join(parts[: i + 1])}' is not a section")
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError:
            value = raw
        node[parts[-1]] = value
    return data


def _unknown(loc: str, name: str, allowed: list[str]) -> str:
    close = difflib.get_close_matches(name, allowed, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    return f"unknown field '{loc}'{hint}; allowed: {', '.join(allowed)}"


def format_validation_error(exc: ValidationError) -> str:
    """One line naming the first offending field and the allowed values."""
    err = exc.errors()[0]
    loc = _tags([str(p) for p in err["loc"] if not isinstance(p, int)])
    dotted = ".".join(loc) or "<root>"
    if err["type"] == "extra_forbidden":
        return _unknown(dotted, loc[-1], _fields_at(loc[:-1]))
    msg = err["msg"].removeprefix("Value error, ")
    inner = re.match(r"^'([A-Za-z0-9_]+)' (.*)$", msg)  # unit errors name the field inside the section
    if inner:
        return f"field '{dotted}.{inner.group(1)}' {inner.group(2)}" if loc else f"field '{inner.group(1)}' {inner.group(2)}"
    if err["type"] == "literal_error":
        return f"field '{dotted}': {msg} (got {err.get('input')!r})"
    if dotted == "<root>" or msg.startswith(loc[-1] if loc else "\0") or "'" in msg[:40]:
        return msg if dotted == "<root>" else f"field '{dotted}': {msg}"
    return f"field '{dotted}': {msg} (got {err.get('input')!r})"


def load_scene(source: str | Path, overrides: list[str] | None = None) -> SceneConfig:
    """Preset name or YAML path + overrides -> validated SceneConfig. Raises ConfigError."""
    data = apply_overrides(_read_source(source), overrides)
    try:
        return SceneConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc)) from None
    except ValueError as exc:  # from unit parsing inside validators
        raise ConfigError(str(exc).splitlines()[0]) from None


def config_json(cfg: SceneConfig) -> str:
    """Canonical JSON of a resolved config (sorted keys), as embedded in recordings."""
    return json.dumps(cfg.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))

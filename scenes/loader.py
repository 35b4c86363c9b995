"""Load a scene: a preset name or a YAML file, plus `key=value` overrides, validated into SceneConfig.

Errors come out as ConfigError with one line that names the field and what is allowed.
"""

from __future__ import annotations

import difflib
import json
import re
import typing
from pathlib import Path
from typing import Any

import yaml
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


def _union_members(ann: Any) -> list[type[BaseModel]]:
    """The models of a (discriminated) union annotation, or [ann] for a model, or []."""
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return [ann]
    out = []
    for a in typing.get_args(ann):
        out += _union_members(a)
    return out


def _fields_at(path: list[str]) -> list[str]:
    """Allowed field names at a dotted path inside SceneConfig (for error messages); a union of sensor
    families lists the fields of all its members."""
    models: list[type[BaseModel]] = [SceneConfig]
    for part in path:
        models = [m for m in models if part in m.model_fields]
        if not models:
            return []
        models = [x for m in models for x in _union_members(m.model_fields[part].annotation)]
    return sorted({f for m in models for f in m.model_fields})


def _strip_union_tags(loc: list[str]) -> list[str]:
    """pydantic puts the discriminator tag into error locations ('sensor', 'ntype', 'layer'): drop it."""
    out: list[str] = []
    models: list[type[BaseModel]] = [SceneConfig]
    for part in loc:
        if len(models) > 1 and any(getattr(m.model_fields.get("family"), "default", None) == part for m in models):
            models = [m for m in models if m.model_fields["family"].default == part]
            continue
        out.append(part)
        models = [m for m in models if part in m.model_fields]
        models = [x for m in models for x in _union_members(m.model_fields[part].annotation)]
    return out


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


_BOUND_ERRORS = ("finite_number", "greater_than", "greater_than_equal", "less_than", "less_than_equal")


def _constraints(ann: Any) -> list[Any]:
    """The annotated_types bounds (Gt, Ge, Lt, Le) inside an annotation: Annotated[float, Field(...)], a list of
    those, or an Optional of those."""
    import annotated_types as at

    out: list[Any] = []
    if typing.get_origin(ann) is typing.Annotated:
        for meta in typing.get_args(ann)[1:]:
            out += [m for m in getattr(meta, "metadata", [meta]) if isinstance(m, (at.Gt, at.Ge, at.Lt, at.Le))]
        return out
    for a in typing.get_args(ann):
        out += _constraints(a)
    return out


def allowed_range(loc: list[str]) -> str:
    """'0 < value <= 0.1' for the float field at a dotted location inside SceneConfig ('' when unknown)."""
    import annotated_types as at

    models: list[type[BaseModel]] = [SceneConfig]
    for part in loc[:-1]:
        models = [x for m in models if part in m.model_fields for x in _union_members(m.model_fields[part].annotation)]
    fields = [m.model_fields[loc[-1]] for m in models if loc and loc[-1] in m.model_fields]
    if not fields:
        return ""
    f = fields[0]
    cons = list(f.metadata) + _constraints(f.annotation)
    lo = next((f"{c.gt:g} < " for c in cons if isinstance(c, at.Gt)), "") or next(
        (f"{c.ge:g} <= " for c in cons if isinstance(c, at.Ge)), "")
    hi = next((f" < {c.lt:g}" for c in cons if isinstance(c, at.Lt)), "") or next(
        (f" <= {c.le:g}" for c in cons if isinstance(c, at.Le)), "")
    return f"a finite number, {lo}value{hi}" if lo or hi else "a finite number (not inf or nan)"


def format_validation_error(exc: ValidationError) -> str:
    """One line naming the first offending field and the allowed values."""
    err = exc.errors()[0]
    loc = _strip_union_tags([str(p) for p in err["loc"] if not isinstance(p, int)])
    dotted = ".".join(loc) or "<root>"
    if err["type"] == "union_tag_invalid":
        tags = err.get("ctx", {}).get("expected_tags", "")
        return f"field '{dotted}.family': {err.get('ctx', {}).get('tag')!r} is not a sensor family (allowed: {tags})"
    if err["type"] == "extra_forbidden":
        return _unknown(dotted, loc[-1], _fields_at(loc[:-1]))
    msg = err["msg"].removeprefix("Value error, ")
    inner = re.match(r"^'([A-Za-z0-9_]+)' (.*)$", msg)  # unit errors name the field inside the section
    if inner:
        return f"field '{dotted}.{inner.group(1)}' {inner.group(2)}" if loc else f"field '{inner.group(1)}' {inner.group(2)}"
    if err["type"] in _BOUND_ERRORS:
        allowed = allowed_range(loc)
        if allowed:
            return f"field '{dotted}': got {err.get('input')!r}; allowed: {allowed}"
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
    d = cfg.model_dump(mode="json")
    if not (d.get("randomize") or {}).get("params"):  # no randomize section: the JSON (and sha) of before it existed
        d.pop("randomize", None)
    return json.dumps(d, sort_keys=True, separators=(",", ":"))

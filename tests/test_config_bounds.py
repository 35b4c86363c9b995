"""Every float field of every scene config rejects inf, nan and absurd values (one line naming the field and
the allowed range); on the command line: exit 2, nothing written, no MUJOCO_LOG.TXT (issue 17, item 5)."""

from __future__ import annotations

import typing

import pytest
from pydantic import BaseModel
from typer.testing import CliRunner

from piezotwin.cli import app
from scenes import ConfigError, load_scene
from scenes.config import SceneConfig
from scenes.loader import _union_members

PRESET_OF_FAMILY = {"cnt_pdms": "cnt_pdms", "fabric": "fabric_1", "ntype": "ntype", "velostat": "velostat"}


def _is_float(ann: typing.Any) -> bool:
    if ann is float:
        return True
    if typing.get_origin(ann) is typing.Annotated:
        return _is_float(typing.get_args(ann)[0])
    if typing.get_origin(ann) in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        return any(_is_float(a) for a in typing.get_args(ann) if a is not type(None))
    return False


def _float_fields(model: type[BaseModel], prefix: str, family: str | None, out: list) -> list:
    """(preset, dotted path, is_list) of every float or list-of-float field below `model`."""
    for name, f in model.model_fields.items():
        ann0 = typing.get_args(f.annotation)[0] if typing.get_origin(f.annotation) is typing.Annotated else f.annotation
        if typing.get_origin(ann0) is dict:  # keyed by free names (randomize.params): swept in test_scene_randomize
            continue
        members = _union_members(f.annotation)
        if members:
            for m in members:
                fam = m.model_fields["family"].default if "family" in m.model_fields else family
                _float_fields(m, f"{prefix}{name}.", fam, out)
            continue
        ann = f.annotation
        is_list = typing.get_origin(ann) is list
        if _is_float(typing.get_args(ann)[0] if is_list else ann):
            for fam in ([family] if family else list(PRESET_OF_FAMILY)[:1]):
                out.append((PRESET_OF_FAMILY[fam], prefix + name, is_list))
    return out


FIELDS = _float_fields(SceneConfig, "", None, [])


def test_the_sweep_covers_every_family():
    assert len(FIELDS) > 90
    assert {p for p, _, _ in FIELDS} == set(PRESET_OF_FAMILY.values())


@pytest.mark.parametrize("value", ["inf", "-inf", ".nan", "nan", "1e30", "-1e30"])
@pytest.mark.parametrize("preset, path, is_list", FIELDS, ids=[f"{p}:{f}" for p, f, _ in FIELDS])
def test_every_float_field_rejects_non_finite_and_absurd(preset, path, is_list, value):
    with pytest.raises(ConfigError) as ei:
        load_scene(preset, [f"{path}={'[' + value + ']' if is_list else value}"])
    msg = str(ei.value)
    assert "\n" not in msg and f"'{path}'" in msg, msg
    assert "allowed:" in msg, msg


def test_message_names_field_and_range():
    with pytest.raises(ConfigError, match=r"field 'pad.thickness_m': got 'inf'; allowed: a finite number, 0 < value <= 0.1"):
        load_scene("cnt_pdms", ["pad.thickness_m=inf"])


def test_presets_stay_inside_the_bounds():
    from scenes import list_presets

    for p in list_presets():
        load_scene(p)


@pytest.mark.parametrize("override", [
    "pad.thickness_m=inf", "pad.youngs_modulus_pa=inf", "pad.thickness_m=1e30", "pad.youngs_modulus_pa=nan",
    "sampling.physics_timestep_s=1e-12", "protocol.frequencies_hz=[.inf]",
])
def test_cli_exit_2_nothing_written_no_mujoco_log(tmp_path, monkeypatch, override):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, ["generate", "cnt_pdms", "-o", "ds", "--set", override])
    assert res.exit_code == 2, res.output
    field = override.split("=")[0]
    assert f"'{field}'" in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no ds/, no MUJOCO_LOG.TXT

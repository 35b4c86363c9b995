"""What the viewers show, read from a recording: per-taxel fields of one episode, in real units.

numpy + sensors.data.recording only (no pyvista): `simulate.pictures.render` and `simulate.pictures.export` build meshes from
this, and tests can check the numbers without rendering.

A *field* is a recorded channel mapped onto the taxels, shape (T, N):
  * channels with dims ("time", "taxel") are used as they are;
  * channels with dims ("time", "channel") are spread onto the taxels through the `/sensor` attribute
    `taxel_channel` (N,) (every taxel shows the value of the channel it is wired to; cnt_pdms has one
    channel for the whole pad, so its resistance colours the pad uniformly, frame by frame).
Families whose channels have other shapes register a mapper in `FIELD_MAPPERS` (family -> "module:fn",
fn(rec, ep_id, channel) -> (T, n) array, or ((T, n) array, caption)); n need not be the taxel count (the
N-type columns are (T, 36 x 3)): the family's geometry knows where each value sits. See
simulate/pictures/fields_families.py.
"""

from __future__ import annotations

import importlib
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensors.data.recording import Recording


@dataclass(frozen=True)
class FieldSpec:
    """How a field is labelled: recorded channel, display label, display unit and the factor SI -> display."""

    channel: str
    label: str
    unit: str  # display unit (shown on the scalar bar)
    scale: float  # display value = SI value * scale
    cmap: str = "viridis"


FIELDS: dict[str, FieldSpec] = {
    "deformation": FieldSpec("deformation", "deformation", "µm", 1e6, "viridis"),
    "pressure": FieldSpec("pressure", "pressure", "kPa", 1e-3, "plasma"),
    "strain": FieldSpec("strain", "compressive strain", "%", 100.0, "cividis"),
    "resistance": FieldSpec("resistance", "resistance", "ohm", 1.0, "coolwarm"),
    "force_taxel": FieldSpec("force_taxel", "taxel force", "mN", 1e3, "plasma"),
}

# family -> "module:function" mapping a channel onto the taxels (see module docstring); one line per family
FIELD_MAPPERS: dict[str, str] = {
    "fabric": "simulate.pictures.fields_families:fabric_field",
    "velostat": "simulate.pictures.fields_families:velostat_field",
    "ntype": "simulate.pictures.fields_families:ntype_field",
}


class FieldError(ValueError):
    """A requested field, episode or time does not exist in the recording (one-line message)."""


def field_names() -> list[str]:
    return list(FIELDS)


def _default_mapper(rec: Recording, ep_id: str, channel: str) -> np.ndarray:
    data = rec.read(ep_id, channel)
    dims = rec.dim_names(ep_id, channel)
    if dims == ("time", "taxel"):
        return np.asarray(data, dtype=np.float64)
    if dims == ("time", "channel"):
        tc = rec.sensor_attrs.get("taxel_channel")
        if tc is None:
            raise FieldError(f"channel '{channel}' is per readout channel but /sensor has no taxel_channel map")
        return np.asarray(data, dtype=np.float64)[:, np.asarray(tc, dtype=np.int64)]
    raise FieldError(f"channel '{channel}' has dims {dims}; no mapping onto taxels for this family")


def _map(rec: Recording, ep_id: str, channel: str) -> tuple[np.ndarray, str | None]:
    fam = rec.sensor_attrs.get("family", "")
    if fam in FIELD_MAPPERS:
        module, fn = FIELD_MAPPERS[fam].split(":")
        out = getattr(importlib.import_module(module), fn)(rec, ep_id, channel)
        if isinstance(out, tuple):
            return np.asarray(out[0], dtype=np.float64), out[1]
        return np.asarray(out, dtype=np.float64), None
    return _default_mapper(rec, ep_id, channel), None


def map_to_taxels(rec: Recording, ep_id: str, channel: str) -> np.ndarray:
    """(T, N) SI values of `channel` on the taxels (or on the family's own value sites, see FIELD_MAPPERS)."""
    return _map(rec, ep_id, channel)[0]


@dataclass
class EpisodeView:
    """One episode of a recording, ready to draw. SI units throughout; T samples, N taxels."""

    path: str
    family: str
    ep_id: str
    config: dict[str, Any]  # the resolved scene config (pad, indenter, ...)
    sensor_attrs: dict[str, Any]
    time_s: np.ndarray  # (T,)
    force_n: np.ndarray  # (T,) total reference force
    position_m: np.ndarray  # (T, 3) indenter lowest point, world frame
    deformation_m: np.ndarray  # (T, N) + into the pad
    fields: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T, N) SI
    units: dict[str, str] = field(default_factory=dict)  # name -> SI unit as recorded
    notes: dict[str, str] = field(default_factory=dict)  # name -> caption (e.g. spread from readout channels)

    @property
    def n_samples(self) -> int:
        return int(self.time_s.shape[0])

    def index_at(self, t_s: float) -> int:
        """Nearest sample to time t_s (s); FieldError outside the episode."""
        t0, t1 = float(self.time_s[0]), float(self.time_s[-1])
        dt = float(self.time_s[1] - self.time_s[0]) if self.n_samples > 1 else 0.0
        if not (t0 - dt / 2 <= t_s <= t1 + dt / 2):
            raise FieldError(f"--time {t_s:g} s is outside episode {self.ep_id} (allowed: {t0:g} .. {t1:g} s)")
        return int(np.argmin(np.abs(self.time_s - t_s)))

    def peak_index(self) -> int:
        """Sample of the largest total force (the default frame to show)."""
        return int(np.argmax(self.force_n)) if self.force_n.size else 0


def resolve_episode(rec: Recording, episode: str | int | None) -> str:
    """Episode id from an index ('3', 3) or an id ('ep-000003'); default the first. FieldError if absent."""
    ids = rec.episode_ids
    if episode is None:
        return ids[0]
    s = str(episode)
    if s in ids:
        return s
    try:
        k = int(s)
    except ValueError:
        raise FieldError(f"no episode '{s}' in {rec.path} (allowed: 0..{len(ids) - 1} or an id like {ids[0]})") from None
    if not 0 <= k < len(ids):
        raise FieldError(f"episode {k} is out of range: {rec.path} has {len(ids)} episodes (allowed: 0..{len(ids) - 1})")
    return ids[k]


def load_episode(rec: Recording, episode: str | int | None = None, fields: list[str] | None = None) -> EpisodeView:
    """Read the channels needed to draw one episode; `fields` defaults to every known field present."""
    ep = resolve_episode(rec, episode)
    have = set(rec.channels(ep))
    want = list(FIELDS) if fields is None else list(fields)
    for name in want:
        if name not in FIELDS:
            raise FieldError(f"unknown field '{name}' (allowed: {', '.join(FIELDS)})")
        if fields is not None and FIELDS[name].channel not in have:
            raise FieldError(f"episode {ep} has no '{FIELDS[name].channel}' channel (has {', '.join(sorted(have))})")
    for need in ("time", "deformation"):
        if need not in have:
            raise FieldError(f"episode {ep} has no '{need}' channel: nothing to draw")
    T = rec.shape(ep, "time")[0]
    out: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    notes: dict[str, str] = {}
    for name in want:
        ch = FIELDS[name].channel
        if ch in have:
            out[name], note = _map(rec, ep, ch)
            units[name] = rec.units(ep, ch)
            if note:
                notes[name] = note
            elif rec.dim_names(ep, ch) == ("time", "channel"):
                nc = rec.shape(ep, ch)[1]
                notes[name] = (f"{name}: {nc} readout channel{'s' if nc != 1 else ''} over "
                               f"{out[name].shape[1]} taxels, shown on the taxels wired to {'them' if nc != 1 else 'it'}")
    force = rec.read(ep, "force").astype(np.float64) if "force" in have else np.zeros(T)
    if force.ndim > 1:
        force = force.reshape(T, -1).sum(axis=1)
    pos = rec.read(ep, "position").astype(np.float64) if "position" in have else np.full((T, 3), np.nan)
    cfg = rec.config
    return EpisodeView(
        path=str(rec.path),
        family=str(rec.sensor_attrs.get("family", cfg.get("sensor", {}).get("family", "?"))),
        ep_id=ep,
        config=cfg,
        sensor_attrs=dict(rec.sensor_attrs),
        time_s=rec.read(ep, "time").astype(np.float64),
        force_n=force,
        position_m=pos,
        deformation_m=map_to_taxels(rec, ep, "deformation"),
        fields=out,
        units=units,
        notes=notes,
    )


def nice_exaggeration(max_deformation_m: float, thickness_m: float, target_fraction: float = 0.3) -> float:
    """The round factor (1, 2, 5 x 10^k, >= 1) nearest (in log scale) to the one that shows the largest
    deflection as `target_fraction` of the thickness: a 150 µm dent in a 5 mm pad is invisible at true scale."""
    if max_deformation_m <= 0 or thickness_m <= 0:
        return 1.0
    raw = target_fraction * thickness_m / max_deformation_m
    if raw <= 1.0:
        return 1.0
    k = np.floor(np.log10(raw))
    cands = np.array([1.0, 2.0, 5.0, 10.0]) * 10**k
    return float(cands[np.argmin(np.abs(np.log(cands / raw)))])


def describe(view: EpisodeView) -> str:
    """One line: family, file, episode (for titles)."""
    return f"{view.family} · {view.ep_id}"


def config_section(view: EpisodeView, key: str) -> dict[str, Any]:
    sec = view.config.get(key, {})
    return json.loads(sec) if isinstance(sec, str) else dict(sec)

"""The scene's ``randomize`` section: per-episode parameter distributions for `piezotwin generate`.

    randomize:
      params:
        sensor.mechanics.creep_amplitude: {kind: uniform, low: 0.05, high: 0.3}
        placement.x_m: {kind: uniform, low: -0.004, high: 0.004}

Each key is a dotted path to a float field of the scene (the value overrides it for one episode) or a
placement of the press (``placement.x_m`` / ``placement.y_m``: the indenter centre on the pad, replacing the
``indenter.position_jitter_m`` draw). Paths under ``sensor.`` (the film law, creep, noise, the readout's gain)
and ``protocol.`` apply per episode; ``pad.*`` and ``indenter.*`` change the MuJoCo model that a batch of
episodes shares, so they are refused here (one scene per tip, or `simulate/generation/chain_gen.py`).
Distributions have bounded support (uniform, loguniform, choice) and both ends of it are validated against
the field's own bounds, so every draw is a valid scene.

Draws come from ``numpy.random.default_rng([episode_seed, 0x5A9D])`` (the stream of scenes.randomize, apart
from the protocol's stream 0 and the noise's stream 1), keys in sorted order: one root seed fixes every
episode's values, independent of batching. They are recorded per episode as attrs ``rand.<path>``.
An empty section changes nothing (the config JSON omits it; no draw is made).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from scenes.base import Between, Strict

STREAM = 0x5A9D
PLACEMENT = ("placement.x_m", "placement.y_m")
PER_EPISODE_PREFIXES = ("sensor.", "protocol.")


class ParamDist(Strict):
    """A bounded distribution of one scene value."""

    kind: Literal["uniform", "loguniform", "choice"] = "uniform"
    low: Between(-1000000000.0, 1000000000.0) | None = None
    high: Between(-1000000000.0, 1000000000.0) | None = None
    values: Annotated[list[Between(-1000000000.0, 1000000000.0)], Field(min_length=1, max_length=1000)] | None = None

    @model_validator(mode="after")
    def _check(self) -> ParamDist:
        if self.kind == "choice":
            if not self.values:
                raise ValueError("choice needs values")
        else:
            if self.low is None or self.high is None or not self.low <= self.high:
                raise ValueError(f"{self.kind} needs low <= high")
            if self.kind == "loguniform" and not self.low > 0:
                raise ValueError("loguniform needs low > 0")
        return self

    def support(self) -> tuple[float, float]:
        return (min(self.values), max(self.values)) if self.kind == "choice" else (float(self.low), float(self.high))

    def draw(self, rng: np.random.Generator) -> float:
        if self.kind == "uniform":
            return float(rng.uniform(self.low, self.high))
        if self.kind == "loguniform":
            return float(np.exp(rng.uniform(np.log(self.low), np.log(self.high))))
        return float(self.values[int(rng.integers(len(self.values)))])


class RandomizeConfig(Strict):
    """Per-episode distributions, keyed by dotted scene path (see the module docstring)."""

    params: Annotated[dict[str, ParamDist], Field(max_length=64)] = Field(default_factory=dict)

    def empty(self) -> bool:
        return not self.params


def _get(obj: Any, path: str) -> Any:
    for part in path.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"randomize.params: {path!r} is not a field of the scene")
        obj = getattr(obj, part)
    return obj


def with_values(cfg: Any, values: dict[str, float]) -> Any:
    """A copy of the scene with the dotted paths set (validated: pydantic raises on a value out of bounds)."""
    if not values:
        return cfg
    d = cfg.model_dump()
    for path, v in values.items():
        if path in PLACEMENT:
            continue
        node = d
        *head, last = path.split(".")
        for part in head:
            node = node[part]
        node[last] = v
    return type(cfg).model_validate(d)


def check(cfg: Any) -> None:
    """Each key names a per-episode float field (or a placement) and both ends of its support make a valid scene."""
    r = cfg.randomize
    if r is None or r.empty():
        return
    for path, dist in r.params.items():
        if path in PLACEMENT:
            lo, hi = dist.support()
            half = (cfg.pad.size_x_m if path.endswith("x_m") else cfg.pad.size_y_m) / 2
            if lo < -half or hi > half:
                raise ValueError(f"randomize.params.{path}: support [{lo}, {hi}] m leaves the pad (+-{half} m)")
            continue
        if not path.startswith(PER_EPISODE_PREFIXES):
            raise ValueError(f"randomize.params: {path!r}: only sensor.*, protocol.* and placement.x_m/y_m vary per "
                             "episode (pad and indenter are the MuJoCo model a batch shares)")
        cur = _get(cfg, path)
        if isinstance(cur, bool) or not isinstance(cur, (int, float)):
            raise ValueError(f"randomize.params: {path!r} is not a number (it is {type(cur).__name__})")
        for v in dist.support():
            try:
                with_values(cfg.model_copy(update={"randomize": None}), {path: v})
            except Exception as exc:  # noqa: BLE001 - reported with the path
                raise ValueError(f"randomize.params.{path}: {v} is not a valid value: {exc}") from None


def draw(cfg: Any, seed: int) -> dict[str, float]:
    """One episode's values (empty when the scene has no randomize section)."""
    r = getattr(cfg, "randomize", None)
    if r is None or r.empty():
        return {}
    rng = np.random.default_rng([int(seed) & (2**63 - 1), STREAM])
    return {k: r.params[k].draw(rng) for k in sorted(r.params)}

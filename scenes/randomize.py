"""Per-episode parameter distributions (domain randomization), drawn from the episode seed.

A ``Randomization`` names, for each randomized quantity, a distribution (``Dist``): fixed, uniform,
loguniform, normal, lognormal (``median`` and ``log_sd``) or choice. ``draw(rand, seed)`` returns one
episode's values (a dict of floats, JSON-ready, recorded per episode as HDF5 attributes by the generator)
from ``numpy.random.default_rng([seed, 0x5A9D])``, so one root seed fixes every episode (the episode seed
is ``sensors.data.manifest.episode_seed(root_seed, k)``, stream 0x5A9D kept apart from the protocol and noise
streams). `piezotwin fit` writes one around the fitted chain (bootstrap spread of the parameters, the press
placement spread, the board's rest level, noise); `simulate/generation/chain_gen.py` uses it.
Quantities (all optional; units in the names):
  gain_log            offset of ln r0 per episode (board gain / film part; with sim2real run_level the run's own
                      level u_run of the hierarchical press levels, sensors.chain_fit.run_level_sd), normal
  level_log_sd        press-to-press placement spread over the film (std of ln level per press)
  miss_prob           share of presses that miss the active area (no response)
  tip_area_scale      tip area relative to the fitted one (r0 ~ 1/A, F_c ~ A)
  exponent, creep_amplitude, creep_force_n, tau_min_s, tau_max_s: the film law and creep
  full_scale          the readout's full scale (the Lupasic board: its rest level)
  noise_scale         readout noise relative to the fitted one
  slope_level_coef, slope_press_sd: each press's own sensitivity, ds_j = coef l_j + N(0, sd^2) added to its
                      d ln R / d ln F (sensors.chain_fit.press_slope_spread; chain_gen.press_slopes)
  peak_force_n, rise_s, hold_s, fall_s, gap_s: the press protocol (per press, drawn per episode's stream)
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["Dist", "Randomization", "draw", "draw_one"]

STREAM = 0x5A9D


class Dist(BaseModel):
    model_config = ConfigDict(extra="forbid")

    kind: Literal["fixed", "uniform", "loguniform", "normal", "lognormal", "choice"] = "fixed"
    value: float | None = None  # fixed
    low: float | None = None  # uniform / loguniform
    high: float | None = None
    mean: float | None = None  # normal
    sd: float | None = None
    median: float | None = None  # lognormal
    log_sd: float | None = None
    values: list[float] | None = None  # choice

    @model_validator(mode="after")
    def _check(self):
        need = {"fixed": ("value",), "uniform": ("low", "high"), "loguniform": ("low", "high"),
                "normal": ("mean", "sd"), "lognormal": ("median", "log_sd"), "choice": ("values",)}[self.kind]
        miss = [k for k in need if getattr(self, k) is None]
        if miss:
            raise ValueError(f"{self.kind} distribution needs {', '.join(miss)}")
        if self.kind in ("uniform", "loguniform") and not self.low <= self.high:
            raise ValueError("low must be <= high")
        if self.kind == "loguniform" and not self.low > 0:
            raise ValueError("loguniform needs low > 0")
        if (self.sd is not None and self.sd < 0) or (self.log_sd is not None and self.log_sd < 0):
            raise ValueError("spreads must be >= 0")
        if self.kind == "choice" and not self.values:
            raise ValueError("choice needs at least one value")
        return self


def draw_one(d: Dist, rng: np.random.Generator) -> float:
    k = d.kind
    if k == "fixed":
        return float(d.value)
    if k == "uniform":
        return float(rng.uniform(d.low, d.high))
    if k == "loguniform":
        return float(np.exp(rng.uniform(np.log(d.low), np.log(d.high))))
    if k == "normal":
        return float(rng.normal(d.mean, d.sd))
    if k == "lognormal":
        return float(d.median * np.exp(rng.normal(0.0, d.log_sd)))
    return float(d.values[int(rng.integers(len(d.values)))])


class Randomization(BaseModel):
    """Distributions per quantity (see the module docstring); absent quantities keep the fitted value."""

    model_config = ConfigDict(extra="forbid")

    episode: dict[str, Dist] = Field(default_factory=dict)  # drawn once per episode
    press: dict[str, Dist] = Field(default_factory=dict)  # drawn once per press (protocol)
    boot: list[dict[str, float]] = Field(default_factory=list)  # joint parameter draws (bootstrap replicates)


def draw(rand: Randomization, seed: int) -> tuple[dict[str, float], np.random.Generator]:
    """One episode's values: a bootstrap replicate (joint, keeps the parameters' correlations) if any, then
    the episode distributions (they override). Returns (values, rng) where rng goes on to draw the presses."""
    rng = np.random.default_rng([int(seed) & (2**63 - 1), STREAM])
    out: dict[str, float] = {}
    if rand.boot:
        b = int(rng.integers(len(rand.boot)))
        out.update({k: float(v) for k, v in rand.boot[b].items()})
        out["boot_replicate"] = float(b)
    for k in sorted(rand.episode):
        out[k] = draw_one(rand.episode[k], rng)
    return out, rng

"""Randomized generation with the identified chain (sensors/chain_fit.py): press sequences -> reading.

Each episode k: seed = episode_seed(root_seed, k); its parameters drawn by scenes.randomize.draw (a
bootstrap replicate of the fit, the board gain, the tip area, the rest level, the noise), then a sequence
of presses (peak force, rise, hold, fall, gap from the Randomization's press distributions), each landing
at its own place on the film (ln level ~ N(0, level_log_sd); a miss with probability miss_prob), forward
through sensors.chain_fit.simulate_reading with the readout noise. Written as one recording (source "sim")
with ``sensor`` ([T, 1], the reading, the real board's units) and ``force`` (N, recorded the chain's
label_latency_s late, as the rig records it); the seed and every drawn
value are episode attributes. A fast alternative to the MuJoCo pipeline for one tip on one taxel/film,
the case of a press rig (no contact mechanics: the recorded force is the input, as in the fit).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from scenes.randomize import Randomization, draw, draw_one
from sensors.chain_fit import ChainParams, shift_label, simulate_reading
from sensors.data.manifest import episode_seed

__all__ = ["episode", "generate_chain", "press_protocol"]


def _smooth(n: int) -> np.ndarray:
    u = (np.arange(n) + 1) / max(n, 1)
    return u * u * (3 - 2 * u)


def press_protocol(rand: Randomization, rng: np.random.Generator, duration_s: float, dt: float):
    """Force [T] (N) and per-sample press index (-1 between presses)."""
    f: list[np.ndarray] = []
    idx: list[np.ndarray] = []
    pr = rand.press
    t, j = 0.0, 0

    def d(name, default):
        return draw_one(pr[name], rng) if name in pr else default

    gap0 = int(d("gap_s", 1.0) / dt)
    f.append(np.zeros(gap0))
    idx.append(np.full(gap0, -1))
    t = gap0 * dt
    while t < duration_s:
        pk = d("peak_force_n", 10.0)
        nr, nh, nf, ng = (max(1, int(d(k, v) / dt)) for k, v in (("rise_s", 0.5), ("hold_s", 1.0), ("fall_s", 0.1), ("gap_s", 1.0)))
        hold = pk * (1 + 0.02 * np.cumsum(rng.standard_normal(nh)) / np.sqrt(nh))  # small drift of the rig
        seg = np.concatenate([pk * _smooth(nr), np.maximum(hold, 0), pk * _smooth(nf)[::-1] * (hold[-1] / pk), np.zeros(ng)])
        f.append(seg)
        idx.append(np.concatenate([np.full(nr + nh + nf, j), np.full(ng, -1)]))
        t += len(seg) * dt
        j += 1
    return np.concatenate(f), np.concatenate(idx)


def press_slopes(force: np.ndarray, pid: np.ndarray, lev: np.ndarray, p: ChainParams, vals: dict,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """Each press's own sensitivity (contact variation, sensors.chain_fit.press_slope_spread; Holm 1967): the
    offset ds_j = slope_level_coef l_j + N(0, slope_press_sd^2) of d ln R / d ln F, pivoted at the press's peak
    (its plateau level stays l_j): ln R gains ds_j ln(F_eff / F_eff,peak). Returns (ds [presses], ln-level
    addition [T]) or None when neither quantity is randomized (the rng then draws nothing: older scenes keep
    their streams)."""
    sd, coef = float(vals.get("slope_press_sd", 0.0)), float(vals.get("slope_level_coef", 0.0))
    if sd <= 0 and coef == 0:
        return None
    n = len(lev)
    # |ds| <= half the exponent: the film law stays a falling power law (estimate: 3 sd of the measured 0.16)
    ds = np.clip(coef * lev + rng.normal(0.0, max(sd, 0.0), n), -0.5 * p.exponent, 0.5 * p.exponent)
    fe = np.maximum(np.asarray(force, np.float64) - p.threshold_force_n, 0.0)
    on = pid >= 0
    pk = np.zeros(n)
    np.maximum.at(pk, pid[on], fe[on])
    j = np.maximum(pid, 0)
    rel = np.where(on & (pk[j] > 0), fe / np.where(pk[j] > 0, pk[j], 1.0), 1.0)
    add = np.where(on, ds[j] * np.log(np.clip(rel, 1e-3, None)), 0.0)
    return ds, add


def episode(p0: ChainParams, rand: Randomization, seed: int, duration_s: float, dt: float) -> tuple[dict, dict[str, Any]]:
    vals, rng = draw(rand, seed)
    p = replace(p0)
    for k in ("exponent", "creep_amplitude", "creep_force_n", "tau_min_s", "tau_max_s", "level_log_sd", "miss_prob",
              "r_series_ohm", "threshold_force_n", "contact_force_n", "tunnel_force_n"):
        if k in vals:
            setattr(p, k, float(vals[k]))
    if "r0_ohm" in vals:
        p.r0_ohm = float(vals["r0_ohm"])
    a = float(vals.get("tip_area_scale", 1.0))
    p.r0_ohm = p.r0_ohm * np.exp(vals.get("gain_log", 0.0)) / a
    p.creep_force_n *= a
    p.contact_force_n *= a  # Hertz: the force at which the contact spans the face ~ E* b^3 / R, ~ the face area
    p.tunnel_force_n *= a  # F_t = A M / (gamma s0): the same strain at the same pressure
    p.noise_sd *= float(vals.get("noise_scale", 1.0))
    fs = float(vals.get("full_scale", p.full_scale))
    force, pid = press_protocol(rand, rng, duration_s, dt)
    n_press = int(pid.max()) + 1
    lev = rng.normal(0.0, p.level_log_sd, n_press)
    miss = rng.random(n_press) < p.miss_prob
    level = np.where(pid >= 0, lev[np.maximum(pid, 0)], 0.0)
    slopes = press_slopes(force, pid, lev, p, vals, rng)
    if slopes is not None:
        level = level + slopes[1]
    lvl = np.where((pid >= 0) & miss[np.maximum(pid, 0)], 60.0, level)  # a miss: the film stays open
    y = simulate_reading(force, dt, p, level=lvl, fs=fs, rng=rng)
    y = np.maximum(y, 1e-6)
    # the label as the rig records it: p.label_latency_s late against the reading (sensors/chain_fit.py, "Label latency")
    ch = {"force": shift_label(force, dt, -p.label_latency_s), "sensor": y}
    attrs = {"seed": int(seed), "randomized": {k: float(v) for k, v in vals.items()}, "n_presses": n_press,
             "n_missed_presses": int(miss.sum()), "press_levels_log": lev.tolist(),
             **({"press_slope_offsets": slopes[0].tolist()} if slopes is not None else {}),
             "chain": {k: v for k, v in p.to_json().items() if k != "times_s"}, "full_scale": fs}
    return ch, attrs


def generate_chain(p0: ChainParams, rand: Randomization, out: str | Path, *, n_episodes: int, root_seed: int,
                   duration_s: float = 60.0, rate_hz: float = 20.0,
                   progress: Callable[[int], None] | None = None) -> Path:
    """Write ``n_episodes`` randomized episodes to the recording ``out`` (atomically)."""
    from sensors.data.recording import Channel, write_recording

    dt = 1.0 / rate_hz
    episodes, ep_attrs = {}, {}
    for k in range(n_episodes):
        s = episode_seed(root_seed, k)
        ch, at = episode(p0, rand, s, duration_s, dt)
        t = np.arange(len(ch["force"])) * dt
        ep = f"ep{k:05d}"
        episodes[ep] = {
            "time": Channel(t, "s", ("time",), "sample clock"),
            "sensor": Channel(ch["sensor"].astype(np.float32)[:, None], "raw", ("time", "channel"),
                              "simulated reading of the identified chain (the real board's units)"),
            "force": Channel(ch["force"].astype(np.float32), "N", ("time",), "applied force (label)"),
        }
        ep_attrs[ep] = at
        if progress:
            progress(k + 1)
    cfg = {"chain": p0.to_json(), "randomization": rand.model_dump(mode="json"), "root_seed": root_seed,
           "duration_s": duration_s, "rate_hz": rate_hz, "n_episodes": n_episodes}
    return write_recording(out, episodes, source="sim", config_json=json.dumps(cfg, sort_keys=True, default=float),
                           root_seed=root_seed, shard_index=0,
                           sensor_attrs={"family": "chain", "sample_rate_hz": rate_hz, "n_channels": 1, "units": "raw"},
                           episode_attrs=ep_attrs, extra_attrs={"generator": "simulate.generation.chain_gen"})

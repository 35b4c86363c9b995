"""Loading protocols: one random draw per episode, and the commanded waveform it implies.

kind "sinusoid": d(t) = d0 [1 - cos(2 pi f (t - settle))] / 2 for `cycles` periods after `settle_s`
(cnt_pdms paper, sect. 3.2). kind "hold": a smooth (raised-cosine) ramp over `ramp_s` to the
amplitude, then hold (creep under force control, relaxation under displacement control).
Displacement is positive into the pad (m); force is positive compressive (N).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from scenes.config import SceneConfig


@dataclass(frozen=True)
class EpisodeProtocol:
    """One episode's loading.

    frequency_hz: sinusoid frequency (drawn also for "hold", where it is unused).
    amplitude: peak displacement d0 (m, control="displacement") or peak force (N, control="force").
    offset_xy_m: (2,) x/y position of the indenter centre on the pad (m).
    n_samples: samples in the episode at cfg.sampling.sample_rate_hz (sample k at t = k / rate).
    control: "displacement" | "force".  kind: "sinusoid" | "hold".
    """

    frequency_hz: float
    amplitude: float
    offset_xy_m: np.ndarray = field(repr=True)
    n_samples: int = 0
    control: str = "displacement"
    kind: str = "sinusoid"
    params: dict = field(default_factory=dict)  # kind-specific draws (levels, hold times, stroke paths, ...)
    index: int | None = None  # the episode's global index k, where the caller knows it (kinds that sweep need it)


def n_samples_for(cfg: SceneConfig, frequency_hz: float) -> int:
    """Samples of an episode at this frequency: round(duration * sample_rate)."""
    return int(round(cfg.episode_duration_s(frequency_hz) * cfg.sampling.sample_rate_hz))


def make_episode_protocol(cfg: SceneConfig, seed: int, index: int | None = None) -> EpisodeProtocol:
    """Draw one episode: frequency from cfg.protocol.frequencies_hz, amplitude U[min, max],
    offset U[-jitter, +jitter]^2, with numpy.random.default_rng(seed). index: the episode's global index
    (seed = episode_seed(root_seed, index)); only kinds that sweep over episodes (velostat_calibration_sweep)
    read it, and they raise without it."""
    rng = np.random.default_rng(seed)
    p = cfg.protocol
    f = float(p.frequencies_hz[int(rng.integers(len(p.frequencies_hz)))])
    amp = float(rng.uniform(p.amplitude_min, p.amplitude_max))
    j = cfg.indenter.position_jitter_m
    off = rng.uniform(-j, j, size=2) if j > 0 else np.zeros(2)
    proto = EpisodeProtocol(
        frequency_hz=f,
        amplitude=amp,
        offset_xy_m=np.asarray(off, dtype=float),
        n_samples=n_samples_for(cfg, f),
        control=p.control,
        kind=p.kind,
        index=None if index is None else int(index),
    )
    if p.kind in PARAM_DRAWS:  # kind-specific draws continue the same stream (kinds without draws unchanged)
        proto = PARAM_DRAWS[p.kind](proto, cfg, rng)
    return proto


def _sinusoid(proto: EpisodeProtocol, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    f = proto.frequency_hz
    on = (tau >= 0.0) & (tau <= cfg.protocol.cycles / f)
    return np.where(on, proto.amplitude * 0.5 * (1.0 - np.cos(2.0 * np.pi * f * tau)), 0.0)


def _hold(proto: EpisodeProtocol, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    u = np.clip(tau / cfg.protocol.ramp_s, 0.0, 1.0)
    return proto.amplitude * 0.5 * (1.0 - np.cos(np.pi * u))


def staircase_turning_points(cfg: SceneConfig, rng: np.random.Generator | None = None) -> list[float]:
    """Turning points of a staircase episode (fabric sect. 3.3), starting and ending at 0 N.

    With protocol.stair_return_points_n: 0 -> r1 -> 0 -> r2 -> 0 ... (the paper's 1-layer series is
    2, 1.27, 1, 1.96, 0.5, 1.7 N). Otherwise: a full cycle 0 -> amplitude_max -> 0, then cycles to random peaks
    U[amplitude_min, amplitude_max], each coming down to 0 or (half the time) to a random valley U[0, peak/2]
    from which the next cycle rises again: return points on the ascending branch and starting points on the
    descending branch both vary. The number of cycles is U{stair_cycles_min..stair_cycles_max}.
    """
    p = cfg.protocol
    step = p.stair_step_n
    if p.stair_return_points_n:
        pts = [0.0]
        for r in p.stair_return_points_n:
            pts += [float(r), 0.0]
        return pts
    rng = rng or np.random.default_rng(0)
    n = int(rng.integers(p.stair_cycles_min, p.stair_cycles_max + 1))
    pts = [0.0, float(p.amplitude_max), 0.0]
    for i in range(1, n):
        # Python's round: numpy's (half to even) on a float, without its per-call cost
        peak = round(rng.uniform(p.amplitude_min, p.amplitude_max) / step * 10) * step / 10
        valley = 0.0 if (i == n - 1 or rng.random() < 0.5) else round(rng.uniform(0, peak / 2) / step) * step
        pts += [max(peak, pts[-1] + step), valley]
    return pts


def staircase_levels(turning_points: list[float], step: float) -> np.ndarray:
    """Force levels visited one dwell each: from each turning point to the next in `step` increments, the
    turning point itself last, on the step grid (0 -> 1.27 -> 0 visits 0.1, ..., 1.2, 1.27, 1.2, ..., 0.1, 0). The first level is turning_points[0]."""
    tp = np.asarray(turning_points, np.float64)
    if len(tp) < 2:
        return np.round(tp[:1].copy(), 9)
    step = float(step)
    eps = 1e-6 * step
    # every segment's grid at once (8192 fabric_1 protocols: a loop over segments cost ~0.3 ms an episode); per
    # segment the grid step * k, k in [floor(lo / step) - 1, ceil(hi / step) + 2), walked downwards on a descending
    # segment, keeps the values strictly inside (lo, hi) by eps, and its end point follows
    a, b = tp[:-1], tp[1:]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    k0, k1 = np.floor(lo / step) - 1, np.ceil(hi / step) + 2
    n = (k1 - k0).astype(np.int64)
    seg = np.repeat(np.arange(len(a)), n)
    within = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    grid = step * np.where((b > a)[seg], k0[seg] + within, k1[seg] - 1 - within)
    keep = (grid > lo[seg] + eps) & (grid < hi[seg] - eps)
    inner = grid[keep]
    levels = np.insert(inner, np.cumsum(np.bincount(seg[keep], minlength=len(a))), b)
    return np.round(np.concatenate([tp[:1], levels]), 9)


def _staircase_draw(cfg: SceneConfig, rng: np.random.Generator) -> dict:
    pts = staircase_turning_points(cfg, rng)
    return {"turning_points_n": pts, "levels_n": staircase_levels(pts, cfg.protocol.stair_step_n)}


def _staircase(proto: EpisodeProtocol, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    """Each level held stair_dwell_s; a new level is applied over stair_ramp_s (raised cosine) at the start
    of its dwell. After the last level (0 N) the force stays at 0."""
    p = cfg.protocol
    levels = proto.params.get("levels_n")
    if levels is None:
        levels = _staircase_draw(cfg, np.random.default_rng(0))["levels_n"]
    levels = np.asarray(levels, float)
    prev = np.concatenate([[0.0], levels])  # level before dwell j
    j = np.clip(np.floor(tau / p.stair_dwell_s).astype(np.int64), 0, len(levels))
    cur = np.concatenate([levels, [0.0]])[j]
    before = prev[j]
    tin = tau - j * p.stair_dwell_s
    u = np.clip(tin / p.stair_ramp_s, 0.0, 1.0) if p.stair_ramp_s > 0 else np.ones_like(tin)
    out = before + (cur - before) * 0.5 * (1.0 - np.cos(np.pi * u))
    return np.where(tau < 0.0, 0.0, out)


def _smooth(t: np.ndarray, t0, t1) -> np.ndarray:
    """Raised-cosine step from 0 at t0 to 1 at t1 (t0, t1 floats, or arrays that broadcast against t)."""
    u = np.clip((t - t0) / np.maximum(t1 - t0, 1e-9), 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(np.pi * u))


def press_stroke_force(ind: dict, t: np.ndarray) -> np.ndarray:
    """Commanded normal force (N) of one indenter of a "press_stroke" episode at absolute times t (or, with
    `stack_indenters`, of one indenter of many episodes: t [1, T] -> [E, T])."""
    if np.ndim(ind["active"]) == 0 and not ind["active"]:
        return np.zeros_like(np.asarray(t, float))
    up = _smooth(t, *ind["t_press_s"])
    down = 1.0 - _smooth(t, *ind["t_release_s"])
    return np.where(ind["active"], ind["force_n"] * up * down, 0.0)


def press_stroke_xy(ind: dict, t: np.ndarray) -> np.ndarray:
    """Commanded x/y (m) of one indenter of a "press_stroke" episode: shape t.shape + (2,) (stacked: [E, T, 2])."""
    t = np.asarray(t, float)
    s = _smooth(t, *ind["t_stroke_s"])
    return np.asarray(ind["xy_m"], float) + s[..., None] * np.asarray(ind["stroke_xy_m"], float)


def stack_indenters(inds: list[dict]) -> dict:
    """One indenter of E episodes as one dict of arrays shaped to broadcast against t [1, T] in
    `press_stroke_force` / `press_stroke_xy` (times and force [E, 1], positions [E, 1, 2]): the same law, the
    same operations element by element, for a batch."""
    col = lambda k: np.array([ind[k] for ind in inds], float)
    return {"active": np.array([bool(ind["active"]) for ind in inds])[:, None], "force_n": col("force_n")[:, None],
            **{k: tuple(col(k).T[:, :, None]) for k in ("t_press_s", "t_stroke_s", "t_release_s")},
            **{k: col(k)[:, None, :] for k in ("xy_m", "stroke_xy_m")}}


def _press_stroke(proto: EpisodeProtocol, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    return press_stroke_force(proto.params["indenters"][0], tau + cfg.protocol.settle_s)


def _draw_press_stroke(proto: EpisodeProtocol, cfg: SceneConfig, rng: np.random.Generator) -> EpisodeProtocol:
    """Per indenter: active (the first always), position on the pad (footprint inside, apart from the others),
    normal force U[amplitude_min, amplitude_max], a stroke in a random direction whose stick displacement
    gives a target shear U[0, shear_ratio_max] x friction x force (ratio > 1 slips), and its timing."""
    from simulate.contact.mjcf import shear_stiffness_n_per_m

    p, ind, pad = cfg.protocol, cfg.indenter, cfg.pad
    half = (ind.size_x_m / 2, ind.size_y_m / 2) if ind.shape == "box" else (ind.radius_m, ind.radius_m)
    lim = np.array([pad.size_x_m / 2 - half[0] - 1e-3, pad.size_y_m / 2 - half[1] - 1e-3]).clip(0.0)
    k_t = shear_stiffness_n_per_m(cfg)
    t_last = (proto.n_samples - 1) / cfg.sampling.sample_rate_hz  # the last frame is at rest
    t_rel = (t_last - p.ramp_s - 0.1 * p.ramp_s, t_last - 0.1 * p.ramp_s)
    placed: list[np.ndarray] = []
    inds = []
    for i in range(ind.count):
        active = bool(i == 0 or rng.random() < p.active_probability)
        for _ in range(50):
            xy = rng.uniform(-lim, lim)
            if all(np.abs(xy - q).max() >= 2 * max(half) for q in placed):
                break
        force = float(rng.uniform(p.amplitude_min, p.amplitude_max))
        theta = float(rng.uniform(0.0, 2.0 * np.pi))
        ratio = float(rng.uniform(0.0, p.shear_ratio_max))
        shear = ratio * ind.friction * force
        delay = float(rng.uniform(0.0, 0.1 * p.duration_s))
        t0 = p.settle_s + delay
        t1 = t0 + p.ramp_s
        direction = np.array([np.cos(theta), np.sin(theta)])
        if active:
            placed.append(xy)
        inds.append({
            "active": active,
            "xy_m": xy.tolist() if active else [float(lim[0]), float(lim[1])],
            "force_n": force if active else 0.0,
            "shear_target_n": (min(shear, ind.friction * force) * direction).tolist() if active else [0.0, 0.0],
            "stroke_xy_m": ((shear / k_t) * direction).tolist() if active else [0.0, 0.0],
            "t_press_s": (t0, t1),
            "t_stroke_s": (t1, min(t1 + p.stroke_s, t_rel[0])),
            "t_release_s": t_rel,
        })
    first = inds[0]
    params = {
        "indenters": inds,
        "stroke_xy_m": first["stroke_xy_m"],  # xy_waveform of the first indenter
        "stroke_start_s": first["t_stroke_s"][0],
        "stroke_end_s": first["t_stroke_s"][1],
    }
    return EpisodeProtocol(
        frequency_hz=proto.frequency_hz, amplitude=first["force_n"], offset_xy_m=np.asarray(first["xy_m"], float),
        n_samples=proto.n_samples, control=proto.control, kind=proto.kind, params=params, index=proto.index,
    )


def _draw_staircase(proto: EpisodeProtocol, cfg: SceneConfig, rng: np.random.Generator) -> EpisodeProtocol:
    return dataclasses.replace(proto, params=_staircase_draw(cfg, rng))


# protocol kind -> waveform(proto, cfg, tau = t - settle_s) of the normal axis; families add their kinds here
WAVEFORMS = {"sinusoid": _sinusoid, "hold": _hold, "staircase": _staircase, "press_stroke": _press_stroke}
# protocol kind -> draw(proto, cfg, rng) -> proto with kind-specific params (after the common draws, so kinds
# without an entry draw exactly as before)
PARAM_DRAWS = {"staircase": _draw_staircase, "press_stroke": _draw_press_stroke}


def target_waveform(proto: EpisodeProtocol, cfg: SceneConfig, t_s: np.ndarray) -> np.ndarray:
    """Commanded displacement (m, + into the pad) or force (N, + compressive) at times t_s (any shape)."""
    t = np.asarray(t_s, dtype=float)
    if proto.kind not in WAVEFORMS:
        raise ValueError(f"protocol kind '{proto.kind}' (allowed: {', '.join(WAVEFORMS)})")
    return WAVEFORMS[proto.kind](proto, cfg, t - cfg.protocol.settle_s)


def _sinusoid_batch(amp: np.ndarray, f: np.ndarray, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    on = (tau >= 0.0) & (tau <= cfg.protocol.cycles / f)
    return np.where(on, amp * 0.5 * (1.0 - np.cos(2.0 * np.pi * f * tau)), 0.0)


def _hold_batch(amp: np.ndarray, f: np.ndarray, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    u = np.clip(tau / cfg.protocol.ramp_s, 0.0, 1.0)
    return amp * 0.5 * (1.0 - np.cos(np.pi * u))


# kinds whose waveform depends only on (amplitude, frequency): the same expressions over (E, 1) columns, so
# a batch of episodes is one array expression, equal bit for bit to the per-episode WAVEFORMS
BATCH_WAVEFORMS = {"sinusoid": _sinusoid_batch, "hold": _hold_batch}


def target_waveforms(protos: list[EpisodeProtocol], cfg: SceneConfig, t_s: np.ndarray) -> np.ndarray:
    """(E, len(t_s)) `target_waveform` of every protocol at the times t_s (1-D); one array expression for
    the kinds in BATCH_WAVEFORMS (the GPU path makes controls for 32k episodes at a time)."""
    t = np.asarray(t_s, dtype=float)
    kinds = {p.kind for p in protos}
    if len(kinds) == 1 and (kind := kinds.pop()) in BATCH_WAVEFORMS:
        amp = np.array([p.amplitude for p in protos])[:, None]
        f = np.array([p.frequency_hz for p in protos])[:, None]
        return BATCH_WAVEFORMS[kind](amp, f, cfg, t[None, :] - cfg.protocol.settle_s)
    return np.stack([target_waveform(p, cfg, t) for p in protos]) if protos else np.zeros((0, t.size))


def xy_waveforms(protos: list[EpisodeProtocol], cfg: SceneConfig, t_s: np.ndarray) -> np.ndarray:
    """(E, len(t_s), 2) `xy_waveform` of every protocol (a broadcast offset where none has a stroke)."""
    t = np.asarray(t_s, dtype=float)
    if any("stroke_xy_m" in p.params for p in protos):
        return np.stack([xy_waveform(p, cfg, t) for p in protos])
    off = np.array([np.asarray(p.offset_xy_m, float) for p in protos]).reshape(len(protos), 1, 2)
    return np.broadcast_to(off, (len(protos), t.size, 2))


def xy_waveform(proto: EpisodeProtocol, cfg: SceneConfig, t_s: np.ndarray) -> np.ndarray:
    """Commanded indenter x/y (m) at times t_s: shape t_s.shape + (2,). A protocol with a tangential
    stroke puts `stroke_xy_m` (the displacement at the end, (2,)) and `stroke_start_s`/`stroke_end_s` in
    params; otherwise the indenter stays at its offset."""
    t = np.asarray(t_s, dtype=float)
    xy = np.broadcast_to(np.asarray(proto.offset_xy_m, float), t.shape + (2,)).copy()
    if "stroke_xy_m" in proto.params:
        t0, t1 = proto.params["stroke_start_s"], proto.params["stroke_end_s"]
        u = np.clip((t - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)
        xy += (0.5 * (1.0 - np.cos(np.pi * u)))[..., None] * np.asarray(proto.params["stroke_xy_m"], float)
    return xy

from simulate.protocols import compression_tester as _velostat

_velostat.register(WAVEFORMS, PARAM_DRAWS)

from simulate.protocols import element_loads as _element_loads

_element_loads.register(WAVEFORMS, PARAM_DRAWS)

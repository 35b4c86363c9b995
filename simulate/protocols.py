"""Loading protocols: one random draw per episode, and the commanded waveform it implies.

kind "sinusoid": d(t) = d0 [1 - cos(2 pi f (t - settle))] / 2 for `cycles` periods after `settle_s`
(cnt_pdms paper, sect. 3.2). kind "hold": a smooth (raised-cosine) ramp over `ramp_s` to the
amplitude, then hold (creep under force control, relaxation under displacement control).
Displacement is positive into the pad (m); force is positive compressive (N).
"""

from __future__ import annotations

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


def n_samples_for(cfg: SceneConfig, frequency_hz: float) -> int:
    """Samples of an episode at this frequency: round(duration * sample_rate)."""
    return int(round(cfg.episode_duration_s(frequency_hz) * cfg.sampling.sample_rate_hz))


def make_episode_protocol(cfg: SceneConfig, seed: int) -> EpisodeProtocol:
    """Draw one episode: frequency from cfg.protocol.frequencies_hz, amplitude U[min, max],
    offset U[-jitter, +jitter]^2, with numpy.random.default_rng(seed)."""
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
    )
    if p.kind in PARAM_DRAWS:  # kind-specific draws (positions, levels, holds) from the same stream
        proto = PARAM_DRAWS[p.kind](proto, cfg, rng)
    return proto


def _sinusoid(proto: EpisodeProtocol, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    f = proto.frequency_hz
    on = (tau >= 0.0) & (tau <= cfg.protocol.cycles / f)
    return np.where(on, proto.amplitude * 0.5 * (1.0 - np.cos(2.0 * np.pi * f * tau)), 0.0)


def _hold(proto: EpisodeProtocol, cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    u = np.clip(tau / cfg.protocol.ramp_s, 0.0, 1.0)
    return proto.amplitude * 0.5 * (1.0 - np.cos(np.pi * u))


# protocol kind -> waveform(proto, cfg, tau = t - settle_s) of the normal axis; families add their kinds here
WAVEFORMS = {"sinusoid": _sinusoid, "hold": _hold}
# protocol kind -> draw(proto, cfg, rng) -> proto with kind-specific params; families add their kinds here
PARAM_DRAWS: dict = {}

from simulate import velostat_protocols as _velostat  # noqa: E402

_velostat.register(WAVEFORMS, PARAM_DRAWS)


def target_waveform(proto: EpisodeProtocol, cfg: SceneConfig, t_s: np.ndarray) -> np.ndarray:
    """Commanded displacement (m, + into the pad) or force (N, + compressive) at times t_s (any shape)."""
    t = np.asarray(t_s, dtype=float)
    if proto.kind not in WAVEFORMS:
        raise ValueError(f"protocol kind '{proto.kind}' (allowed: {', '.join(WAVEFORMS)})")
    return WAVEFORMS[proto.kind](proto, cfg, t - cfg.protocol.settle_s)


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

"""Protocols of a force-controlled compression testing machine for the `velostat` family (paper key
`velostat`, sects. 3.1, 3.2, 4.1, 5.4; machines ZQ-990B / ZQ-20B-1).

Every kind is a piecewise-linear force schedule (`params["knots_t_s"]`, `params["knots_f_n"]`, times from
the end of `settle_s`): the crosshead moves at a loading speed v (1-6 mm/min), which on a contact of
stiffness k (protocol.machine_stiffness_n_per_m, an estimate) ramps the force at k v.

kinds
  velostat_steps        press-hold-release: levels U[amplitude_min, amplitude_max] N, holds
                        U[hold_min_s, hold_max_s], a loading speed per press, rest 2-10 s between presses
                        (Fig. 3a: 1, 3, 5 N held 30 s; Fig. 5: 3 N at 1-6 mm/min).
  velostat_staircase    step_force_n, 2 step_force_n, ... staircase_max_n, step_hold_s per step (Fig. 6).
  velostat_calibration  the 36-unit grid: one unit's centre, 1 N ... amplitude_max in step_force_n steps
                        (sect. 4.1, eq. 10); the unit drawn at random per episode.
  velostat_calibration_sweep  the same staircase, but every unit in turn (the paper calibrates all 36):
                        episode k calibrates unit perm_r[k mod U], r = k div U, perm_r a shuffle of the U units
                        seeded by (root_seed, r); so each round of U consecutive episodes covers every unit
                        once. Needs the episode's global index (EpisodeProtocol.index).
  velostat_site_sweep   the staircase at the sites A-E in turn (sect. 5.4, Fig. 23: each of the four corners and
                        the centre pressed 1-15 N): episode k at SITES_AE[k mod 5], so every 5 consecutive episodes
                        cover A-E once (velostat_staircase draws its site from A-E and random places, and 10
                        episodes may miss one). Needs the episode's global index.
  velostat_mix          one of the three per episode (0.4 / 0.3 / 0.3; estimate): the default dataset.
Positions: the corners A-D (the corner units' centres), the centre E, or uniform over the film (sect. 3.2, 5.4).

This module does not import simulate.protocols.indenter (which registers these kinds), so there is no cycle.
"""

from __future__ import annotations

import dataclasses

import numpy as np

SITES = ("A", "B", "C", "D", "E", "random")
SITES_AE = SITES[:5]  # the paper's test sites (sect. 5.4)
MIX = (("velostat_steps", 0.4), ("velostat_staircase", 0.3), ("velostat_calibration", 0.3))  # estimate
REST_MIN_S, REST_MAX_S = 2.0, 10.0  # estimate: rest between presses


def _units(cfg) -> tuple[int, int]:
    s = cfg.sensor
    return (getattr(s, "units_x", 6), getattr(s, "units_y", 6))


def unit_centres_m(cfg) -> np.ndarray:
    """(U, 2) centres of the calibration units, flat index u = iy * units_x + ix (y slowest)."""
    ux, uy = _units(cfg)
    xs = -cfg.pad.size_x_m / 2 + (np.arange(ux) + 0.5) * cfg.pad.size_x_m / ux
    ys = -cfg.pad.size_y_m / 2 + (np.arange(uy) + 0.5) * cfg.pad.size_y_m / uy
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def site_xy_m(cfg, site: str) -> np.ndarray:
    """Corners A (top left), B (top right), C (bottom right), D (bottom left) at the corner units' centres; E centre."""
    ux, uy = _units(cfg)
    hx = cfg.pad.size_x_m / 2 - cfg.pad.size_x_m / (2 * ux)
    hy = cfg.pad.size_y_m / 2 - cfg.pad.size_y_m / (2 * uy)
    return np.array({"A": (-hx, hy), "B": (hx, hy), "C": (hx, -hy), "D": (-hx, -hy), "E": (0.0, 0.0)}[site])


def ramp_s(cfg, delta_n: float, speed_m_per_s: float) -> float:
    return abs(delta_n) / (cfg.protocol.machine_stiffness_n_per_m * speed_m_per_s)


def knots_steps(cfg, levels, holds, speeds, rests) -> tuple[list[float], list[float]]:
    """Press-hold-release sequence; returns (times, forces) knots from t = 0 (end of settle)."""
    t, f = [0.0], [0.0]
    for lv, h, v, r in zip(levels, holds, speeds, rests):
        t += [t[-1] + ramp_s(cfg, lv, v)]
        f += [lv]
        t += [t[-1] + h, t[-1] + h + ramp_s(cfg, lv, v)]
        f += [lv, 0.0]
        t += [t[-1] + r]
        f += [0.0]
    return t, f


def knots_staircase(cfg, levels, hold_s: float, speed: float, release: bool = True) -> tuple[list[float], list[float]]:
    t, f = [0.0], [0.0]
    for lv in levels:
        t += [t[-1] + ramp_s(cfg, lv - f[-1], speed), None]
        t[-1] = t[-2] + hold_s
        f += [lv, lv]
    if release:
        t += [t[-1] + ramp_s(cfg, f[-1], speed)]
        f += [0.0]
    return t, f


def _position(cfg, rng, site: str) -> np.ndarray:
    if site != "random":
        return site_xy_m(cfg, site)
    m = max(cfg.indenter.size_x_m, 2 * cfg.indenter.radius_m if cfg.indenter.shape == "sphere" else 0.0)
    hx = cfg.pad.size_x_m / 2 - m
    hy = cfg.pad.size_y_m / 2 - m
    return rng.uniform([-hx, -hy], [hx, hy])


def sweep_unit(cfg, index: int) -> int:
    """Unit of episode ``index`` under velostat_calibration_sweep (a shuffled round of all units per U episodes)."""
    n = int(np.prod(_units(cfg)))
    r, k = divmod(int(index), n)
    return int(np.random.default_rng([int(cfg.generation.root_seed), r, 0x5EE9]).permutation(n)[k])


def draw(proto, cfg, rng: np.random.Generator):
    """Fill an EpisodeProtocol of a velostat kind (offset, amplitude, params) from the episode's rng."""
    p = cfg.protocol
    kind = proto.kind
    if kind == "velostat_mix":
        names, w = zip(*MIX)
        kind = names[int(rng.choice(len(names), p=np.asarray(w)))]
    dur = p.duration_s
    speed = float(p.loading_speeds_m_per_s[int(rng.integers(len(p.loading_speeds_m_per_s)))])
    sweep = kind == "velostat_calibration_sweep"
    site_sweep = kind == "velostat_site_sweep"
    if site_sweep:
        if proto.index is None:
            raise ValueError("protocol.kind=velostat_site_sweep needs the episode's global index "
                             "(make_episode_protocol(cfg, seed, index))")
        kind = "velostat_staircase"  # the inner kind: the same staircase
    if sweep:
        if proto.index is None:
            raise ValueError("protocol.kind=velostat_calibration_sweep needs the episode's global index "
                             "(make_episode_protocol(cfg, seed, index))")
        kind = "velostat_calibration"  # the inner kind: the same staircase
    params: dict = {"kind": kind}
    if kind == "velostat_calibration":
        centres = unit_centres_m(cfg)
        u = int(rng.integers(len(centres)))  # drawn either way: the rest of the stream stays the same
        if sweep:
            u = sweep_unit(cfg, proto.index)
        xy = centres[u]
        levels = np.arange(p.step_force_n, p.amplitude_max + 1e-9, p.step_force_n)
        ramps = ramp_s(cfg, levels[-1], speed) * 2
        hold = min(p.step_hold_s, max((dur - ramps) / len(levels), 0.5))
        t, f = knots_staircase(cfg, levels, hold, speed)
        params.update(unit=u, site=f"unit{u}")
    else:
        site = SITES[int(rng.integers(len(SITES)))]  # drawn either way, as the calibration sweep draws its unit
        if site_sweep:
            site = SITES_AE[int(proto.index) % len(SITES_AE)]
        xy = _position(cfg, rng, site)
        params["site"] = site
        if kind == "velostat_staircase":
            levels = np.arange(p.step_force_n, p.staircase_max_n + 1e-9, p.step_force_n)
            t, f = knots_staircase(cfg, levels, p.step_hold_s, speed)
        else:
            levels, holds, speeds, rests = [], [], [], []
            used = 0.0
            while True:
                lv = float(rng.uniform(p.amplitude_min, p.amplitude_max))
                h = float(rng.uniform(p.hold_min_s, p.hold_max_s))
                v = float(p.loading_speeds_m_per_s[int(rng.integers(len(p.loading_speeds_m_per_s)))])
                r = float(rng.uniform(REST_MIN_S, REST_MAX_S))
                need = 2 * ramp_s(cfg, lv, v) + h + r
                if levels and used + need > dur:
                    break
                levels.append(lv), holds.append(h), speeds.append(v), rests.append(r)
                used += need
                if used > dur:
                    break
            t, f = knots_steps(cfg, levels, holds, speeds, rests)
            params["speeds_m_per_s"] = speeds
    params.update(knots_t_s=[float(x) for x in t], knots_f_n=[float(x) for x in f], speed_m_per_s=speed)
    return dataclasses.replace(
        proto, offset_xy_m=np.asarray(xy, float), amplitude=float(max(f)), kind=proto.kind, params=params
    )


def waveform(proto, cfg, tau: np.ndarray) -> np.ndarray:
    """Force (N) at times tau after settle: linear interpolation of the knots, 0 before, last value after."""
    t = np.asarray(proto.params["knots_t_s"], float)
    f = np.asarray(proto.params["knots_f_n"], float)
    return np.where(tau < 0.0, 0.0, np.interp(tau, t, f))


KINDS = ("velostat_steps", "velostat_staircase", "velostat_calibration", "velostat_calibration_sweep", "velostat_site_sweep",
         "velostat_mix")


def register(waveforms: dict, drawers: dict) -> None:
    for k in KINDS:
        waveforms[k] = waveform
        drawers[k] = draw

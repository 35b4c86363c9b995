"""Two measurements behind issue 14's open velostat targets (session 10), on the ideal load field (the commanded
force through simulate.contact.load_field, no MuJoCo) and the numpy sensor chain; writes
bench/results/velostat-units-slow.json.

  units  The Ward elbow on eq. 10's data, one 1-15 N calibration per unit (5 s holds, one random loading speed
         1-6 mm/min per unit as the experiment's calibration sweep draws them; R over each hold's last second), on
         film parts (sensor.film.field_seed) 0-7, with the film's parts of the unit spread switched off one at a
         time: which part of the spread moves the elbow, and by how much the kneedle's choice wins (its score
         (1 - x_k) - y_k at k = 3, 4, 5, see simulate.characterize.velostat.elbow).
  slow   1-15 N staircases, 5 s per step (sect. 5.4's A-E protocol) at corner A and centre E, at 1-6 mm/min: R at
         the end of each ramp and of each hold at 1 vs 6 mm/min, and the force read through a static calibration
         made of the same staircases at all six speeds (geometric mean of R per level: a calibration over mixed
         speeds, as the experiment's sweep is), with the creep on and off. The true film + ITO resistance
         (`resistance`): no readout noise in the comparison.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

import simulate.characterize.velostat as CV
from scenes import load_scene
from simulate.protocols.compression_tester import (
    knots_staircase,
    site_xy_m,
    unit_centres_m,
)

LEVELS = np.arange(1.0, 16.0)
HOLD_S = 5.0
PARTS = list(range(8))
VARIANTS = {"preset": [], "no creep-amplitude field (creep_spread 0)": ["sensor.film.creep_spread=0"],
            "no smooth conductance field (conductance_spread 0)": ["sensor.film.conductance_spread=0"],
            "no creep (amplitude 0)": ["sensor.creep.amplitude=0"],
            "no creep, no smooth field": ["sensor.creep.amplitude=0", "sensor.film.conductance_spread=0"]}


def _run(cfg, knots, xys, field: str):
    sen = CV.make_sensor(cfg, "numpy", "cpu")
    T = max(t[-1] for t, _ in knots)
    protos = [CV._proto(cfg, t, f, xy, T + 1.0) for (t, f), xy in zip(knots, xys)]
    _, out = CV.run(cfg, sen, protos, "ideal")
    r = out[field].astype(float)
    w = int(round(cfg.sampling.sample_rate_hz))  # the hold's last second
    ramp = np.array([[r[j, CV._idx(cfg, t[1 + 2 * i])] for i in range(len(LEVELS))] for j, (t, _) in enumerate(knots)])
    hold = np.array([[r[j, CV._idx(cfg, t[2 + 2 * i]) - w:CV._idx(cfg, t[2 + 2 * i])].mean() for i in range(len(LEVELS))]
                     for j, (t, _) in enumerate(knots)])
    return ramp, hold


def _loglog(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation, extended beyond both ends along the end segments (a reading above the
    calibration's top level is not clipped to it)."""
    y = np.interp(x, xp, fp)
    lo, hi = x < xp[0], x > xp[-1]
    y[lo] = fp[0] + (x[lo] - xp[0]) * (fp[1] - fp[0]) / (xp[1] - xp[0])
    y[hi] = fp[-1] + (x[hi] - xp[-1]) * (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
    return y


def kneedle_scores(heights: np.ndarray, kmax: int = 15) -> dict[str, float]:
    h = np.sort(np.asarray(heights))[::-1][:kmax]
    x = np.arange(kmax) / (kmax - 1)
    y = (h - h[-1]) / max(h[0] - h[-1], 1e-12)
    return {str(k): float((1 - x[k - 1]) - y[k - 1]) for k in (3, 4, 5, 6)}


def units() -> dict:
    from scipy.cluster.hierarchy import linkage

    out = {}
    for name, ov in VARIANTS.items():
        rows = []
        for part in PARTS:
            cfg = load_scene("velostat", [f"sensor.film.field_seed={part}", *ov])
            speeds = np.random.default_rng([part, 10]).integers(1, 7, 36)
            knots = [knots_staircase(cfg, LEVELS, HOLD_S, v * CV.MM_PER_MIN) for v in speeds]
            _, R = _run(cfg, knots, unit_centres_m(cfg), "resistance_measured")
            Z = linkage(R, method="ward")
            rows.append({"part": part, "k_elbow": CV.elbow(Z[:, 2]), "kneedle_score": kneedle_scores(Z[:, 2])})
        ks = [r["k_elbow"] for r in rows]
        out[name] = {"overrides": ov, "k_by_part": ks, "median": float(np.median(ks)),
                     "share_4_6": float(np.mean([4 <= k <= 6 for k in ks])), "parts": rows}
        print(f"units {name}: elbows {ks}", flush=True)
    return out


def slow() -> dict:
    out = {}
    speeds = [1, 2, 3, 4, 5, 6]
    for name, ov in (("preset", []), ("no creep (amplitude 0)", ["sensor.creep.amplitude=0"])):
        cfg = load_scene("velostat", ["sensor.film.field_seed=0", *ov])
        res = {}
        for site in ("A", "E"):
            knots = [knots_staircase(cfg, LEVELS, HOLD_S, v * CV.MM_PER_MIN) for v in speeds]
            ramp, hold = _run(cfg, knots, [site_xy_m(cfg, site)] * len(speeds), "resistance")
            cal = np.exp(np.log(hold).mean(0))
            err = np.exp(_loglog(np.log(hold), np.log(cal[::-1]), np.log(LEVELS[::-1]))) - LEVELS
            res[site] = {
                "r_ramp_end_1_over_6_pct": (100 * (ramp[0] / ramp[-1] - 1)).tolist(),
                "r_hold_end_1_over_6_pct": (100 * (hold[0] / hold[-1] - 1)).tolist(),
                "force_error_by_speed_n": {f"{v}": err[i].tolist() for i, v in enumerate(speeds)},
                "force_error_13_15n_1mm_min_n": err[0, 12:].tolist(),
                "force_error_13_15n_6mm_min_n": err[-1, 12:].tolist(),
            }
            print(f"slow {name} {site}: R hold end 1 vs 6 mm/min at 15 N {res[site]['r_hold_end_1_over_6_pct'][-1]:+.1f} %,"
                  f" force error at 13-15 N 1 mm/min {np.round(err[0, 12:], 2)}", flush=True)
        out[name] = res
    return out


def main() -> None:
    t0 = time.time()
    r = {"levels_n": LEVELS.tolist(), "hold_s": HOLD_S, "parts": PARTS, "units": units(), "slow": slow()}
    r["seconds"] = round(time.time() - t0, 1)
    p = Path(__file__).resolve().parent / "results" / "velostat-units-slow.json"
    p.write_text(json.dumps(r, indent=1))
    print(f"wrote {p} ({r['seconds']} s)")


if __name__ == "__main__":
    main()

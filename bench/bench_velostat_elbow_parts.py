"""Ward elbow of the velostat unit grid over many film parts (issue 14: the paper's Fig. 12 finds about 5 groups;
the experiment's three parts give 3-4): is the film's domain structure (`sensors/velostat/model.py` film_domains,
5 domains of evenly spaced resistivity, an estimate) one that yields 4-6 groups, with the miss a matter of which part?

    PYTHONPATH=. python bench/bench_velostat_elbow_parts.py [--parts 64] [--out bench/results/velostat-elbow-parts.json]

Per part (`sensor.film.field_seed` = 0 .. parts-1): the characterization's unit grid (`simulate.characterize.velostat
.unit_grid`: a 1-15 N staircase at 6 mm/min on each of the 36 unit centres, R at the end of each ramp, Ward linkage,
the kneedle elbow) on the commanded load (`load="ideal"`, no MuJoCo: seconds a part), numpy sensor chain. Also with
the domains' contrast off (`domain_spread=0`: the smooth field alone) for contrast. Writes the elbows and their
histogram."""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np

from scenes import load_scene
from sensors.registry import make_sensor
from simulate.characterize.velostat import unit_grid


def elbows(parts: int, extra: list[str]) -> list[int]:
    out = []
    for s in range(parts):
        cfg = load_scene("velostat", [f"sensor.film.field_seed={s}", *extra])
        out.append(int(unit_grid(cfg, make_sensor(cfg, "numpy", "cpu"), "ideal")[2]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--parts", type=int, default=64)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "velostat-elbow-parts.json")
    a = ap.parse_args()
    t0 = time.perf_counter()
    res = {"parts": a.parts, "protocol": "characterize unit_grid, ideal load, numpy chain", "variants": {}}
    for name, extra in (("preset", []), ("no domains (domain_spread=0)", ["sensor.film.domain_spread=0"])):
        ks = elbows(a.parts, extra)
        hist = dict(sorted(Counter(ks).items()))
        share = float(np.mean([4 <= k <= 6 for k in ks]))
        res["variants"][name] = {"elbows": ks, "histogram": hist, "share_4_to_6": share, "mean": float(np.mean(ks)),
                                 "first_three_parts": ks[:3]}
        print(f"{name}: elbows {hist}, 4-6 in {100 * share:.0f} % of {a.parts} parts, parts 0-2: {ks[:3]}", flush=True)
    res["seconds"] = time.perf_counter() - t0
    a.out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

"""What bounds the creep tracker's K-means silhouette (velostat sect. 3.2, eq. 7; issue 14: >= 0.8, paper 0.931):
the film's creep, the readout noise, or the staircases' own loading ramps.

    python bench/bench_velostat_silhouette.py [--tag cpu]

Twelve Fig. 6 staircases (1-10 N in 1 N steps, 10 s per step, then released) at the sites A-E in turn, through the
preset's film and readout on the ideal load field (the commanded force spread by simulate.contact.load_field, no
MuJoCo; numpy chain), at the experiment's loading speeds (1-6 mm/min, two staircases each) or at one speed. The
creep tracker (learn.models.velostat.CreepTracker) is fitted on them as the experiment fits it (smooth 5, lag 5:
the 0.5 s delta period; conductance domain) and with eq. 3 as printed (one sample). Each variant changes one
thing; where the creep or the cutoff time changes, sensor.creep.amplitude is refitted to the Fig. 22a staircase
error of 5 N (`piezotwin calibrate velostat`'s fit), so every creeping variant keeps the paper's creep size.
Writes bench/results/velostat-silhouette-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SPEEDS_MM_PER_MIN = (1, 2, 3, 4, 5, 6)  # the experiment's (velostat Fig. 5)
# label, scene overrides, speeds (mm/min), creep amplitude: "fit" (refitted to 5 N), "preset" or a number
VARIANTS = (
    ("preset (1-6 mm/min)", [], SPEEDS_MM_PER_MIN, "preset"),
    ("theta_c 1 s (Dieterich & Kilgore's ~1 s)", ["sensor.creep.cutoff_time_s=1.0"], SPEEDS_MM_PER_MIN, "fit"),
    ("readout noise 0", ["sensor.readout.noise_v=0"], SPEEDS_MM_PER_MIN, "preset"),
    ("no creep", [], SPEEDS_MM_PER_MIN, 0.0),
    ("no creep, readout noise 0", ["sensor.readout.noise_v=0"], SPEEDS_MM_PER_MIN, 0.0),
    ("3 mm/min only", [], (3,), "preset"),
    ("6 mm/min only", [], (6,), "preset"),
    ("no creep, 6 mm/min only", [], (6,), 0.0),
    ("20 mm/min only", [], (20,), "preset"),
    ("60 mm/min only", [], (60,), "preset"),
)


def staircases(cfg, speeds):
    from simulate.characterize.velostat import MM_PER_MIN, _proto
    from simulate.protocols.compression_tester import knots_staircase, site_xy_m

    kn = []
    for i, v in enumerate(list(speeds) * (12 // len(speeds))):
        t, f = knots_staircase(cfg, list(range(1, 11)), 10.0, v * MM_PER_MIN)
        kn.append((t, f, site_xy_m(cfg, "ABCDE"[i % 5])))
    dur = max(t[-1] for t, _, _ in kn) + 2.0
    return [_proto(cfg, t, f, xy, dur) for t, f, xy in kn]


def variant(overrides, speeds, amplitude) -> dict:
    from learn.models.velostat import CreepTracker
    from scenes import load_scene
    from sensors.registry import make_sensor
    from simulate.characterize.velostat import _with_amplitude, fit_creep_amplitude, run

    cfg = load_scene("velostat", list(overrides))
    if amplitude == "fit":
        cfg = _with_amplitude(cfg, fit_creep_amplitude(cfg))
    elif amplitude != "preset":
        cfg = _with_amplitude(cfg, float(amplitude))
    _, out = run(cfg, make_sensor(cfg, "numpy", "cpu"), staircases(cfg, speeds), "ideal")
    r = list(out["resistance_measured"].astype(float))
    rec = {"creep_amplitude": cfg.sensor.creep.amplitude}
    for key, kw in (("period_0_5_s", {"smooth": 5, "lag": 5}), ("eq3_as_printed", {"smooth": 1, "lag": 1})):
        tr = CreepTracker(domain="conductance", **kw).fit(r)
        rec[key] = {"silhouette": float(tr.silhouette_), "kmeans_bounds": list(map(float, tr.kmeans_bounds_)),
                    "centres": tr.kmeans.cluster_centers_.ravel().tolist(), "counts": tr.kmeans.counts_.tolist()}
    return rec


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tag", default="cpu")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    a = ap.parse_args()
    t0 = time.perf_counter()
    res = {"host": platform.node(), "staircases": "12 x (1-10 N, 1 N steps, 10 s per step, released), sites A-E in "
           "turn, ideal load field, numpy chain", "paper_silhouette": 0.931, "variants": {}}
    for label, ov, speeds, amp in VARIANTS:
        v = variant(ov, speeds, amp)
        v.update(overrides=ov, speeds_mm_per_min=list(speeds))
        res["variants"][label] = v
        print(f"{label:44s} silhouette {v['period_0_5_s']['silhouette']:.3f} (eq. 3 as printed "
              f"{v['eq3_as_printed']['silhouette']:.3f}), creep amplitude {v['creep_amplitude']:.3f}", flush=True)
    res["seconds"] = time.perf_counter() - t0
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / f"velostat-silhouette-{a.tag}.json").write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {a.out / f'velostat-silhouette-{a.tag}.json'} ({res['seconds']:.0f} s)")


if __name__ == "__main__":
    main()

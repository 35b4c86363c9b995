"""Where the velostat sensor stage's time goes, per part of `VelostatSensor.run`, on one (E, T, N) pressure field.

    python bench/bench_velostat_sensor_stage.py [--episodes 64] [--repeats 3] [--tag cpu]

The GPU feed's plain-CLI run of velostat on the H100 spent 96 s of 148 s in the driver's sensor stage
(`user-cli-h100-s8-velostat-lzf.json`, 8192 episodes x 1505 samples x 144 taxels). This times the stage's parts on
a random field of the preset's taxels and episode length (70 % of taxels unloaded, 0-20 kPa elsewhere), on the sensor's own backend and
device (Warp; the CPU here): the readout noise draw, the film kernel (upload, kernel, download), the readout, the
host force and contact centroid (float64 clip, sum and einsum over the whole field), the unit index, and run() as a
whole; and the GPU path's `run_device()` (session 9) on the same field as a float64 Warp array on the device; best of `repeats`. Writes bench/results/velostat-sensor-stage-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", default="cpu")
    a = ap.parse_args()
    from scenes import load_scene
    from sensors.registry import make_sensor
    from sensors.velostat.kernels import run_readout_warp
    from sensors.velostat.model import readout_numpy

    cfg = load_scene("velostat")
    s = make_sensor(cfg)
    from simulate.protocols.indenter import make_episode_protocol

    E, T, N = a.episodes, make_episode_protocol(cfg, 0).n_samples, s.n_taxels  # the preset's episode length
    rng = np.random.default_rng(0)
    pressure = (rng.random((E, T, N), dtype=np.float32) * 2e4).astype(np.float32)
    pressure[rng.random((E, T, N)) < 0.7] = 0
    seeds = list(range(E))
    noise = s.noise(seeds, T)
    cond = s.conductance(pressure)

    import warp as wp

    field_d = wp.array(pressure.astype(np.float64).reshape(E * T, N), dtype=wp.float64, device=s.device)

    def host_force_centroid():
        p = np.clip(np.asarray(pressure, np.float64), 0, None)
        fz = p.sum(-1) * s.area
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.einsum("etn,nk->etk", p, s.xy) * s.area / fz[..., None]

    parts = {
        "noise draw": lambda: s.noise(seeds, T),
        "film: upload, kernel, download": lambda: s.conductance(pressure),
        "readout": lambda: (readout_numpy(cond, noise, s.rp) if s.backend == "numpy"
                            else run_readout_warp(cond, noise, s.rp, s.device)),
        "force + centroid on the host (float64 clip, sum, einsum)": host_force_centroid,
        "unit index": lambda: s.unit_of(host_force_centroid()),
        "run() whole": lambda: s.run(pressure, seeds),
        # the GPU path since session 9: the float64 load field already on the sensor's device (not timed: the upload)
        "run_device() whole (field on the device)": lambda: s.run_device(field_d, seeds, (E, T)),
    }
    best = {}
    for _ in range(a.repeats):
        for k, fn in parts.items():
            t0 = time.perf_counter()
            fn()
            best[k] = min(best.get(k, float("inf")), time.perf_counter() - t0)
    best["unit index"] -= best["force + centroid on the host (float64 clip, sum, einsum)"]  # it recomputes the centroid
    out = {"what": __doc__.split("\n")[0], "command": f"python bench/bench_velostat_sensor_stage.py --episodes {E} "
           f"--repeats {a.repeats} --tag {a.tag}", "host": platform.node(), "cpus": os.cpu_count(),
           "omp_threads": os.environ.get("OMP_NUM_THREADS"), "backend": s.backend, "device": s.device,
           "episodes": E, "samples": T, "taxels": N,
           "seconds": best, "ms_per_episode": {k: 1e3 * v / E for k, v in best.items()},
           "share_of_run": {k: v / best["run() whole"] for k, v in best.items() if not k.startswith("run")}}
    path = Path(__file__).parent / "results" / f"velostat-sensor-stage-{a.tag}.json"
    path.write_text(json.dumps(out, indent=1))
    for k, v in out["ms_per_episode"].items():
        print(f"{k:58s} {v:7.2f} ms/episode")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

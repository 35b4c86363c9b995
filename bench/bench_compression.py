"""Compression of the shards: size and write speed of each `generation.compression` on the same episodes, in one
run, interleaved, against a plain file of the same bytes (fsync'd like the shards).

    python bench/bench_compression.py [--episodes 16] [--repeats 3] [--tag cpu]

Two records: the default preset (15 x 15 taxels, every channel, 0.5 Hz) and the compact 6 x 6 taxel readout of
the GPU bench (time, target, position, contact_force, force_taxel, adc). The episodes are simulated once (C
MuJoCo, Warp CPU) and written by one process (`sensors.data.recording.write_recording`); MB/s counts the raw
bytes of the channels. Writes bench/results/compression-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

CODECS = ("none", "lzf", "gzip", "zstd", "lz4")
COMPACT = ["sensor.readout=taxel", "pad.taxels_x=6", "pad.taxels_y=6",
           "generation.record=[time,target,position,contact_force,force_taxel,adc]"]


def episodes_of(overrides: list[str], n: int) -> tuple[dict, str, int]:
    from scenes import config_json, load_scene
    from sensors.registry import make_sensor
    from simulate.generation.run import simulate_episodes

    cfg = load_scene("cnt_pdms", ["protocol.frequencies_hz=[0.5]"] + overrides)
    sensor = make_sensor(cfg, "warp", "cpu")
    res = simulate_episodes(cfg, list(range(n)), [f"ep-{k:06d}" for k in range(n)], sensor, threads=2)
    return {r.ep_id: r.channels for r in res}, config_json(cfg), sum(r.protocol.n_samples for r in res)


def measure(eps: dict, cfg_json: str, repeats: int, tmp: Path) -> dict:
    from sensors.data.recording import write_recording

    raw = sum(c.data.nbytes for e in eps.values() for c in e.values())
    times: dict[str, list[float]] = {c: [] for c in CODECS + ("plain file",)}
    sizes: dict[str, int] = {}
    for _ in range(repeats):  # interleaved: the machine's load drifts alike for every codec
        for comp in CODECS:
            t0 = time.perf_counter()
            p = write_recording(tmp / f"{comp}.h5", eps, source="sim", config_json=cfg_json, root_seed=0,
                                shard_index=0, sensor_attrs={"family": "cnt_pdms"}, compression=comp)
            times[comp].append(time.perf_counter() - t0)
            sizes[comp] = p.stat().st_size
            p.unlink()
        t0 = time.perf_counter()
        blob = np.concatenate([c.data.reshape(-1).view(np.uint8) for e in eps.values() for c in e.values()])
        with open(tmp / "raw.bin", "wb") as f:
            f.write(blob.tobytes())
            f.flush()
            os.fsync(f.fileno())
        times["plain file"].append(time.perf_counter() - t0)
        (tmp / "raw.bin").unlink()
    out = {"raw_bytes": raw}
    for k, ts in times.items():
        med = statistics.median(ts)
        out[k] = {"seconds_median": med, "seconds": ts, "MB_per_s": raw / med / 1e6,
                  **({"file_bytes": sizes[k], "file_to_raw": sizes[k] / raw} if k in sizes else {})}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", default="cpu")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    from sensors.warp_setup import init_warp

    init_warp()
    res: dict = {"host": platform.node(), "cpus": os.cpu_count(), "load_average_before": os.getloadavg(),
                 "episodes": a.episodes, "repeats": a.repeats, "codecs": list(CODECS), "records": {}}
    with tempfile.TemporaryDirectory(dir=a.out.parent) as tmp:
        for name, ov in (("default preset (15 x 15, all channels)", []), ("compact 6 x 6 taxel record", COMPACT)):
            eps, cj, samples = episodes_of(ov, a.episodes)
            r = measure(eps, cj, a.repeats, Path(tmp))
            r["samples"] = samples
            res["records"][name] = r
            print(f"{name}: {r['raw_bytes'] / 1e6:.1f} MB raw, {samples} samples")
            for k in CODECS + ("plain file",):
                ratio = f", file {r[k]['file_to_raw']:.2f} x raw" if "file_to_raw" in r[k] else ""
                print(f"  {k:10s} {r[k]['MB_per_s']:7.0f} MB/s ({samples / r[k]['seconds_median']:.3g} samples/s){ratio}")
    res["load_average_after"] = os.getloadavg()
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"compression-{a.tag}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

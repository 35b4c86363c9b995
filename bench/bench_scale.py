"""Generation at scale on CPU: time per stage, then throughput against batch size with 1 and 2 worker
processes (the local executor of simulate/executors.py), memory per episode, scaling efficiency.

    python bench/bench_scale.py [--batches 4,8,16] [--workers 1,2] [--shards-per-worker 2]

"Sensor sample" = one 100 Hz frame of one episode (all taxels and channels, with labels), written to
disk; "taxel-steps" = sensor samples x taxels. Batch size = episodes per shard (one batched MuJoCo rollout
and one sensor-kernel launch). Each point runs `shards-per-worker x workers` shards in an already started
pool (worker start-up, ~3 s for imports + Warp init, is reported apart), so 1 and 2 workers do the same
work per worker and scaling efficiency = throughput(2) / (2 x throughput(1)).
Writes bench/results/scale-cpu.json.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import resource
import shutil
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

PRESET = "cnt_pdms"
BASE = ["protocol.frequencies_hz=[0.5]"]


def _cfg(batch: int, n_episodes: int):
    from scenes import load_scene

    return load_scene(PRESET, BASE + [f"generation.episodes={n_episodes}", f"generation.episodes_per_shard={batch}"])


def stage_profile(batch: int, threads: int = 1) -> dict:
    """Seconds per stage for one shard of `batch` episodes in this process (after a warm-up shard)."""
    from scenes import config_json
    from sensors.manifest import episode_seed
    from sensors.recording import write_recording
    from sensors.registry import make_sensor
    from sensors.warp_setup import init_warp
    from simulate import contact
    from simulate.protocols import make_episode_protocol
    from simulate.run import _channels

    init_warp()
    cfg = _cfg(batch, batch)
    sensor = make_sensor(cfg)
    seeds = [episode_seed(0, k) for k in range(batch)]
    protos = [make_episode_protocol(cfg, s) for s in seeds]
    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(2):  # the first is a warm-up (kernel load, page cache)
            t = {}
            t0 = time.perf_counter()
            sens, target = contact.simulate_sensors(cfg, protos, threads)
            t["mujoco_rollout"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            orig = contact.simulate_sensors
            contact.simulate_sensors = lambda *a, **k: (sens, target)
            try:
                batch_ld = contact.run_episodes(cfg, protos, threads)
            finally:
                contact.simulate_sensors = orig
            t["load_field"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            out = sensor.run_load(batch_ld, seeds)
            t["sensor_chain"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            eps = {f"ep-{j}": _channels(batch_ld, out, j, cfg, sensor) for j in range(batch)}
            t["assemble_channels"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            p = write_recording(Path(tmp) / "s.h5", eps, source="sim", config_json=config_json(cfg), root_seed=0,
                                shard_index=0, sensor_attrs=dict(sensor.attrs()), compression=cfg.generation.compression)
            t["hdf5_write"] = time.perf_counter() - t0
            raw = sum(c.data.nbytes for e in eps.values() for c in e.values())
            res = {"batch": batch, "threads": threads, "seconds": t, "total_s": sum(t.values()),
                   "share": {k: v / sum(t.values()) for k, v in t.items()}, "raw_bytes_per_episode": raw / batch,
                   "file_bytes_per_episode": p.stat().st_size / batch}
    return res


def _warm(_: int) -> int:
    """Import and initialise everything a worker needs (run once per worker before timing)."""
    from sensors.warp_setup import init_warp
    import simulate.executors  # noqa: F401
    import simulate.run  # noqa: F401

    init_warp()
    time.sleep(0.3)
    return os.getpid()


def _task(cfg, out: str, shard: int) -> tuple[int, float, int]:
    from simulate.executors import shard_task

    _, n, _ = shard_task(cfg, out, shard, threads=1)
    return n, time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def throughput(batch: int, workers: int, shards_per_worker: int, root: Path) -> dict:
    n_shards = shards_per_worker * workers
    cfg = _cfg(batch, batch * n_shards)
    out = root / f"b{batch}-w{workers}"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        pids = set(pool.map(_warm, range(workers)))
        t_start = time.perf_counter() - t0
        t1 = time.perf_counter()
        futs = [pool.submit(_task, cfg, str(out), s) for s in range(n_shards)]
        res = [f.result() for f in futs]
        wall = time.perf_counter() - t1
    from simulate.protocols import make_episode_protocol

    T = make_episode_protocol(cfg, 0).n_samples
    samples = sum(r[0] for r in res) * T
    taxels = cfg.pad.n_taxels
    file_bytes = sum(p.stat().st_size for p in out.glob("shard-*.h5"))
    shutil.rmtree(out, ignore_errors=True)
    return {
        "batch": batch, "workers": workers, "distinct_worker_pids": len(pids), "shards": n_shards,
        "episodes": batch * n_shards, "samples": samples, "seconds": wall, "worker_startup_s": t_start,
        "samples_per_s": samples / wall, "taxel_steps_per_s": samples * taxels / wall,
        "episodes_per_s": batch * n_shards / wall, "file_MB_per_s": file_bytes / wall / 1e6,
        "worker_peak_rss_MB": max(r[2] for r in res) / 1024,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--batches", default="4,8,16")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--shards-per-worker", type=int, default=2)
    ap.add_argument("--profile-batch", type=int, default=16)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    batches = [int(x) for x in a.batches.split(",")]
    workers = [int(x) for x in a.workers.split(",")]

    prof = stage_profile(a.profile_batch)
    print(f"stages, one process, 1 MuJoCo thread, {a.profile_batch} episodes x 620 samples (225 taxels):")
    for k, v in prof["seconds"].items():
        print(f"  {k:18s} {v:6.3f} s  {prof['share'][k]:5.1%}")
    print(f"  raw {prof['raw_bytes_per_episode'] / 1e6:.2f} MB/episode, file {prof['file_bytes_per_episode'] / 1e6:.2f} MB/episode")

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for b in batches:
            for w in workers:
                r = throughput(b, w, a.shards_per_worker, Path(tmp))
                rows.append(r)
                print(f"batch {b:3d} workers {w}: {r['samples_per_s']:8.0f} samples/s  {r['taxel_steps_per_s']:.3g} taxel-steps/s  "
                      f"{r['episodes_per_s']:.2f} episodes/s  peak RSS {r['worker_peak_rss_MB']:.0f} MB  ({r['seconds']:.1f} s, "
                      f"start-up {r['worker_startup_s']:.1f} s)")
    eff = {}
    for b in batches:
        one = next((r for r in rows if r["batch"] == b and r["workers"] == 1), None)
        two = next((r for r in rows if r["batch"] == b and r["workers"] == 2), None)
        if one and two:
            eff[str(b)] = two["samples_per_s"] / (2 * one["samples_per_s"])
            print(f"scaling efficiency 1 -> 2 workers at batch {b}: {eff[str(b)]:.0%}")
    # memory per episode: slope of the worker's peak RSS against batch size (1 worker)
    ones = sorted((r["batch"], r["worker_peak_rss_MB"]) for r in rows if r["workers"] == 1)
    mem = None
    if len(ones) >= 2:
        (b0, m0), (b1, m1) = ones[0], ones[-1]
        mem = (m1 - m0) / (b1 - b0)
        print(f"memory per episode (peak RSS slope, batch {b0} -> {b1}): {mem:.1f} MB; "
              f"recorded {prof['raw_bytes_per_episode'] / 1e6:.2f} MB raw, {prof['file_bytes_per_episode'] / 1e6:.2f} MB on disk")
    load = os.getloadavg()
    res = {"host": platform.node(), "cpus": os.cpu_count(), "loadavg_at_end": load, "preset": PRESET,
           "overrides": BASE, "samples_per_episode": 620, "taxels": 225, "stage_profile": prof, "throughput": rows,
           "scaling_efficiency_1_to_2": eff, "memory_per_episode_MB": mem}
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "scale-cpu.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"load average at end {load[0]:.2f} on {os.cpu_count()} cores; wrote {path}")


if __name__ == "__main__":
    main()

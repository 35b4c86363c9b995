"""Generation at scale on CPU: time per stage, then throughput against batch size with 1 and 2 worker
processes (the local executor of simulate/generation/executors.py), memory per episode, scaling efficiency.

    python bench/bench_scale.py [--batches 4,16,32] [--workers 1,2] [--shards-per-worker 2]

"Sensor sample" = one 100 Hz frame of one episode (all taxels and channels, with labels), written to
disk; "taxel-steps" = sensor samples x taxels. Batch size = episodes per shard; write_shard runs them in
up to 4 batched MuJoCo rollouts + sensor-kernel launches (`simulate.generation.run.shard_batches`, >= 4 episodes
each) and writes batch i while batch i+1 runs. Each point runs `shards-per-worker x workers` shards in
an already started pool (worker start-up and one untimed warm-up shard per worker are reported apart),
so 1 and 2 workers do the same work per worker and scaling efficiency = throughput(2) / (2 x throughput(1)).
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


DEVICE = "cpu"  # Warp device of the sensor kernels (--device); MuJoCo always runs on the CPU


def stage_profile(batch: int, threads: int = 1) -> dict:
    """Seconds per stage for `batch` episodes in one batch in this process (after a warm-up), then the same
    shard end to end through write_shard (pipelined)."""
    from scenes import config_json
    from sensors.data.manifest import episode_seed
    from sensors.data.recording import write_recording
    from sensors.registry import make_sensor
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field import load_field as contact
    from simulate.generation.run import channel_arrays, episode_channels
    from simulate.protocols.indenter import make_episode_protocol

    init_warp()
    cfg = _cfg(batch, batch)
    sensor = make_sensor(cfg, "warp", DEVICE)
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
            arrays = channel_arrays(batch_ld, out, cfg, sensor)
            eps = {f"ep-{j}": episode_channels(arrays, j) for j in range(batch)}
            t["assemble_channels"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            p = write_recording(Path(tmp) / "s.h5", eps, source="sim", config_json=config_json(cfg), root_seed=0,
                                shard_index=0, sensor_attrs=dict(sensor.attrs()), compression=cfg.generation.compression)
            t["hdf5_write"] = time.perf_counter() - t0
            raw = sum(c.data.nbytes for e in eps.values() for c in e.values())
            res = {"episodes": batch, "threads": threads, "seconds": t, "total_s": sum(t.values()),
                   "share": {k: v / sum(t.values()) for k, v in t.items()}, "raw_bytes_per_episode": raw / batch,
                   "file_bytes_per_episode": p.stat().st_size / batch}
        # the whole shard through simulate.generation.run.write_shard, interleaved: PIPELINE_PARTS = 1 (simulate all, then
        # write: the old path) vs the default (batches; HDF5 write of batch i in a thread while batch i+1 runs);
        # peak Python/numpy heap (tracemalloc) per episode
        import tracemalloc

        from simulate.contact.mjcf import build_mjcf
        from simulate.generation import run

        mjcf = build_mjcf(cfg)
        default_parts = run.PIPELINE_PARTS
        times: dict[int, list[float]] = {1: [], default_parts: []}
        heap: dict[int, float] = {}
        try:
            for rep in range(3):
                for parts in times:
                    run.PIPELINE_PARTS = parts
                    tracemalloc.start()
                    t0 = time.perf_counter()
                    run.write_shard(cfg, Path(tmp), 0, sensor, mjcf, threads=threads)
                    times[parts].append(time.perf_counter() - t0)
                    heap[parts] = tracemalloc.get_traced_memory()[1] / batch / 1e6
                    tracemalloc.stop()
        finally:
            run.PIPELINE_PARTS = default_parts
        n = len(out["force"][0])
        res["write_shard"] = {
            str(parts): {"batches": [sl.stop - sl.start for sl in _batches(run, batch, parts)],
                         "seconds_min": min(v), "seconds": v, "samples_per_s": batch * n / min(v),
                         "peak_heap_MB_per_episode": heap[parts]}
            for parts, v in times.items()
        }
        res["pipeline_speedup"] = min(times[1]) / min(times[default_parts])
    return res


def _batches(run, n: int, parts: int) -> list[slice]:
    old = run.PIPELINE_PARTS
    run.PIPELINE_PARTS = parts
    try:
        return run.shard_batches(n)
    finally:
        run.PIPELINE_PARTS = old


def _set_parts(parts: int) -> None:
    from simulate.generation import run

    run.PIPELINE_PARTS = parts


def _warm(cfg, out: str, parts: int, device: str) -> int:
    """Import, initialise Warp and build the sensor for `cfg` in this worker (one scratch shard, untimed)."""
    from simulate.generation.executors import shard_task

    global DEVICE
    DEVICE = device
    _set_parts(parts)
    shard_task(cfg, out, 0, device=DEVICE, threads=1)
    time.sleep(0.2)
    return os.getpid()


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)  # this process, all its threads
    return r.ru_utime + r.ru_stime


def _task(cfg, out: str, shard: int) -> tuple[int, float, float]:  # runs with the worker's PIPELINE_PARTS
    from simulate.generation.executors import shard_task

    c0 = _cpu_s()
    _, n, _ = shard_task(cfg, out, shard, device=DEVICE, threads=1)
    return n, time.perf_counter(), _cpu_s() - c0


def throughput(batch: int, workers: int, shards_per_worker: int, root: Path, parts: int) -> dict:
    from simulate.generation import run

    n_shards = shards_per_worker * workers
    cfg = _cfg(batch, batch * n_shards)
    out = root / f"b{batch}-w{workers}"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        pids = set(pool.map(_warm, [cfg] * workers, [str(root / f"warm-{i}") for i in range(workers)], [parts] * workers,
                              [DEVICE] * workers))
        t_start = time.perf_counter() - t0
        t1 = time.perf_counter()
        futs = [pool.submit(_task, cfg, str(out), s) for s in range(n_shards)]
        res = [f.result() for f in futs]
        wall = time.perf_counter() - t1
    from simulate.protocols.indenter import make_episode_protocol

    T = make_episode_protocol(cfg, 0).n_samples
    samples = sum(r[0] for r in res) * T
    taxels = cfg.pad.n_taxels
    file_bytes = sum(p.stat().st_size for p in out.glob("shard-*.h5"))
    shutil.rmtree(out, ignore_errors=True)
    return {
        "batch": batch, "pipeline_parts": parts,
        "rollout_batches": [sl.stop - sl.start for sl in _batches(run, batch, parts)], "workers": workers, "distinct_worker_pids": len(pids), "shards": n_shards,
        "episodes": batch * n_shards, "samples": samples, "seconds": wall, "worker_startup_s": t_start,
        "samples_per_s": samples / wall, "taxel_steps_per_s": samples * taxels / wall,
        "episodes_per_s": batch * n_shards / wall, "file_MB_per_s": file_bytes / wall / 1e6,
        "cpu_s": sum(r[2] for r in res), "cpu_us_per_sample": sum(r[2] for r in res) / samples * 1e6,
        "loadavg_1min_after": os.getloadavg()[0],
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--batches", default="4,16,32")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--shards-per-worker", type=int, default=2)
    ap.add_argument("--profile-batch", type=int, default=16)
    ap.add_argument("--parts", default="4,1", help="PIPELINE_PARTS values to sweep (1 = no write overlap)")
    ap.add_argument("--device", default="cpu", help="Warp device of the sensor kernels: cpu | cuda")
    ap.add_argument("--tag", default="cpu", help="results file: results/scale-<tag>.json")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    global DEVICE
    DEVICE = "cuda:0" if a.device == "cuda" else a.device
    batches = [int(x) for x in a.batches.split(",")]
    workers = [int(x) for x in a.workers.split(",")]
    a.parts = [int(x) for x in a.parts.split(",")]

    prof = stage_profile(a.profile_batch)
    print(f"stages, one process, 1 MuJoCo thread, {a.profile_batch} episodes x 620 samples (225 taxels):")
    for k, v in prof["seconds"].items():
        print(f"  {k:18s} {v:6.3f} s  {prof['share'][k]:5.1%}")
    print(f"  raw {prof['raw_bytes_per_episode'] / 1e6:.2f} MB/episode, file {prof['file_bytes_per_episode'] / 1e6:.2f} MB/episode")
    for parts, ws in prof["write_shard"].items():
        print(f"  write_shard end to end, PIPELINE_PARTS={parts} (batches {ws['batches']}): {ws['seconds_min']:.3f} s, "
              f"{ws['samples_per_s']:.0f} samples/s, peak heap {ws['peak_heap_MB_per_episode']:.2f} MB/episode")
    print(f"  pipelined write: {prof['pipeline_speedup']:.2f}x faster than simulate-all-then-write")

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for parts in a.parts:
            for b in batches:
                for w in workers:
                    r = throughput(b, w, a.shards_per_worker, Path(tmp), parts)
                    rows.append(r)
                    print(f"parts {parts} shard of {b:3d} episodes {r['rollout_batches']!s:14s} workers {w}: "
                          f"{r['samples_per_s']:7.0f} samples/s  {r['taxel_steps_per_s']:.3g} taxel-steps/s  "
                          f"{r['episodes_per_s']:.2f} episodes/s  {r['file_MB_per_s']:.1f} MB/s to disk  {r['cpu_us_per_sample']:.0f} CPU-us/sample "
                          f"({r['seconds']:.1f} s, load {r['loadavg_1min_after']:.1f})")
    eff: dict = {}
    for parts in a.parts:
        for b in batches:
            one = next((r for r in rows if (r["batch"], r["workers"], r["pipeline_parts"]) == (b, 1, parts)), None)
            two = next((r for r in rows if (r["batch"], r["workers"], r["pipeline_parts"]) == (b, 2, parts)), None)
            if one and two:
                k = f"parts{parts}_shard{b}"
                eff[k] = {"wall": two["samples_per_s"] / (2 * one["samples_per_s"]),
                          "cpu": one["cpu_us_per_sample"] / two["cpu_us_per_sample"]}
                print(f"scaling 1 -> 2 workers, PIPELINE_PARTS={parts}, shard of {b}: efficiency {eff[k]['wall']:.0%} "
                      f"(CPU time per sample 1 worker / 2 workers: {eff[k]['cpu']:.0%})")
    mem = prof["write_shard"]
    print("memory per episode (peak Python/numpy heap of write_shard / episodes): "
          + ", ".join(f"PIPELINE_PARTS={k}: {v['peak_heap_MB_per_episode']:.2f} MB" for k, v in mem.items())
          + f"; recorded {prof['raw_bytes_per_episode'] / 1e6:.2f} MB raw, {prof['file_bytes_per_episode'] / 1e6:.2f} MB on disk")
    load = os.getloadavg()
    cpu_model = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                      if ln.startswith("model name")), platform.processor())
    res = {"host": platform.node(), "cpu_model": cpu_model, "cpus": os.cpu_count(), "sensor_device": DEVICE, "loadavg_at_end": load, "preset": PRESET,
           "overrides": BASE, "samples_per_episode": 620, "taxels": 225, "stage_profile": prof, "throughput": rows,
           "scaling_efficiency_1_to_2": eff,
           "memory_per_episode_MB": {k: v["peak_heap_MB_per_episode"] for k, v in mem.items()}}
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"scale-{a.tag}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"load average at end {load[0]:.2f} on {os.cpu_count()} cores; wrote {path}")


if __name__ == "__main__":
    main()

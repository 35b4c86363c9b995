"""One GPU, end to end: MuJoCo Warp worlds -> load field -> Warp sensor chain on CUDA -> HDF5 on disk.

    python bench/bench_gpu_pipeline.py --device cuda:0 [--worlds 1024,4096,16384] [--episodes 8192] [--workers 1,4]

Scene: the cnt_pdms preset as a 6 x 6 tactile array (sensor.readout = taxel: one bridge + 14-bit ADC per
taxel), 0.5 Hz presses, 100 Hz samples, 1 ms physics steps. A "sensor sample" is one 100 Hz frame of one
episode as written: 36 ADC codes + its labels (time, target, indenter position, net contact force, the 36
per-taxel forces) = `generation.record` below, 252 bytes.

Measured in one run, written to bench/results/gpu-pipeline-<device>.json:
1. physics: MuJoCo Warp world-steps/s against the number of worlds (CUDA graph per sample period), and
   the C MuJoCo rollout on all host cores for the same batch (ratio);
2. equivalence: MuJoCo Warp on the GPU vs C MuJoCo, same episodes (force and position differences);
3. stages: seconds per stage for one batch in one process (controls, physics, load field, sensor chain,
   HDF5 write) -> what limits the throughput;
4. end to end: `simulate.generation.executors.generate` (the code `piezotwin generate --physics mujoco_warp` runs)
   with 1..W worker processes sharing the GPU(s) (pinned round-robin when there are several), samples/s and MB/s on disk, against the raw write speed of
   the same bytes to the same disk measured right after (plain file, 64 MiB blocks, fsync at the end in both).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

RECORD = ["time", "target", "position", "contact_force", "force_taxel", "adc"]
BASE = ["protocol.frequencies_hz=[0.5]", "pad.taxels_x=6", "pad.taxels_y=6", "sensor.readout=taxel",
        "generation.compression=none", f"generation.record=[{','.join(RECORD)}]"]


def _cfg(extra: list[str], device: str | None = None):
    """The bench scene; with a device, the contact stage runs on MuJoCo Warp there."""
    from scenes import load_scene

    if device is not None:
        extra = ["generation.physics=mujoco_warp", f"generation.device={'cuda' if device.startswith('cuda') else 'cpu'}", *extra]
    return load_scene("cnt_pdms", BASE + extra)


def physics(device: str, worlds: list[int], n_samples: int) -> dict:
    """World-steps/s of MuJoCo Warp against batch size, and C MuJoCo (all cores) on the largest batch <= 4096."""
    from simulate.contact.load_field import _initial_states, build_model, episode_controls, simulate_sensors
    from simulate.contact.mujoco_warp import WarpWorlds, box_primitive_for
    from simulate.protocols.indenter import make_episode_protocol

    cfg = _cfg([])
    sub = cfg.sampling.substeps
    m = build_model(cfg)
    out = {"n_samples": n_samples, "substeps": sub, "mujoco_warp": {}}
    for W in worlds:
        protos = [make_episode_protocol(cfg, s) for s in range(W)]
        nstep = (n_samples - 1) * sub
        ctrl, _ = episode_controls(cfg, protos, nstep)
        st, s0 = _initial_states(m, cfg, protos, ctrl[:, 0])
        ww = WarpWorlds(m, W, device, box_primitive=box_primitive_for(cfg.protocol.control))
        ww.run(st[:, 1:1 + m.nq], ctrl[:, : 5 * sub], s0, sub, 6)  # compile + capture outside the timing
        t0 = time.perf_counter()
        ww.run(st[:, 1:1 + m.nq], ctrl, s0, sub, n_samples)
        dt = time.perf_counter() - t0
        out["mujoco_warp"][W] = {"seconds": dt, "world_steps_per_s": W * nstep / dt, "samples_per_s": W * (n_samples - 1) / dt}
        print(f"MuJoCo Warp {W:6d} worlds: {W * nstep / dt:.3g} world-steps/s, {W * (n_samples - 1) / dt:.3g} samples/s")
        del ww
    W = max(w for w in worlds if w <= 4096) if any(w <= 4096 for w in worlds) else worlds[0]
    protos = [make_episode_protocol(cfg, s) for s in range(W)]
    threads = os.cpu_count() or 1
    t0 = time.perf_counter()
    simulate_sensors(cfg, protos, threads=threads)
    dt = time.perf_counter() - t0
    nstep = (protos[0].n_samples - 1) * sub
    out["mujoco_c"] = {"worlds": W, "threads": threads, "world_steps_per_s": W * nstep / dt}
    print(f"C MuJoCo rollout, {W} episodes on {threads} threads: {W * nstep / dt:.3g} world-steps/s")
    return out


def _physics_worker(args) -> tuple[float, int]:
    """In a fresh process pinned to one GPU: MuJoCo Warp world-steps/s for `worlds` worlds."""
    gpu, worlds, n_samples = args
    os.environ["CUDA_VISIBLE_DEVICES"] = str(gpu)
    from sensors.warp_setup import init_warp

    init_warp()
    from simulate.contact.load_field import _initial_states, build_model, episode_controls
    from simulate.contact.mujoco_warp import WarpWorlds, box_primitive_for
    from simulate.protocols.indenter import make_episode_protocol

    cfg = _cfg([])
    sub, m = cfg.sampling.substeps, build_model(cfg)
    protos = [make_episode_protocol(cfg, s) for s in range(worlds)]
    nstep = (n_samples - 1) * sub
    ctrl, _ = episode_controls(cfg, protos, nstep)
    st, s0 = _initial_states(m, cfg, protos, ctrl[:, 0])
    ww = WarpWorlds(m, worlds, "cuda:0", box_primitive=box_primitive_for(cfg.protocol.control))
    ww.run(st[:, 1:1 + m.nq], ctrl[:, : 5 * sub], s0, sub, 6)
    t0 = time.perf_counter()
    ww.run(st[:, 1:1 + m.nq], ctrl, s0, sub, n_samples)
    return worlds * nstep / (time.perf_counter() - t0), gpu


def physics_multi_gpu(worlds: int, n_samples: int) -> dict:
    """MuJoCo Warp on 1 GPU, then on every GPU at once (one process each): aggregate world-steps/s."""
    import multiprocessing as mp

    import warp as wp

    n = wp.get_cuda_device_count()
    ctx = mp.get_context("spawn")
    out = {"worlds_per_gpu": worlds, "gpus": n}
    for k in sorted({1, n}):
        with ctx.Pool(k) as pool:
            rates = pool.map(_physics_worker, [(g, worlds, n_samples) for g in range(k)])
        out[f"{k}_gpu"] = {"world_steps_per_s": sum(r for r, _ in rates), "per_gpu": [r for r, _ in rates]}
        print(f"MuJoCo Warp on {k} GPU(s), {worlds} worlds each: {sum(r for r, _ in rates):.3g} world-steps/s")
    if n > 1:
        out["scaling_efficiency"] = out[f"{n}_gpu"]["world_steps_per_s"] / (n * out["1_gpu"]["world_steps_per_s"])
    return out


def equivalence(device: str, n: int = 16) -> dict:
    from simulate.contact.load_field import simulate_sensors
    from simulate.protocols.indenter import make_episode_protocol

    cfg = _cfg([])
    cfg_w = _cfg([], device)
    protos = [make_episode_protocol(cfg, s) for s in range(n)]
    a, _ = simulate_sensors(cfg, protos)
    b, _ = simulate_sensors(cfg_w, protos)
    fmax = float(np.abs(a[..., 4:7]).max())
    res = {"episodes": n, "force_max_n": fmax, "force_max_abs_diff_n": float(np.abs(a[..., 4:7] - b[..., 4:7]).max()),
           "position_max_abs_diff_m": float(np.abs(a[..., 0:3] - b[..., 0:3]).max())}
    print(f"MuJoCo Warp ({device}) vs C MuJoCo: force max |diff| {res['force_max_abs_diff_n']:.3g} N of {fmax:.3g} N, "
          f"position {res['position_max_abs_diff_m']:.3g} m")
    return res


def stages(device: str, batch: int) -> dict:
    """Seconds per stage for one batch of `batch` episodes in this process (after a warm-up), along the path
    `generate` takes: physics for the whole batch, then load field and sensor chain per SENSOR_SLICE on the
    device (fields left there for the chain), channels, HDF5."""
    from sensors.data.manifest import episode_seed
    from sensors.data.recording import RecordingWriter
    from sensors.registry import make_sensor
    from simulate.contact.load_field import load_field as contact
    from simulate.protocols.indenter import make_episode_protocol
    from simulate.generation.run import SENSOR_SLICE, EpisodeResult, _episode_attrs, channel_arrays, episode_channels

    cfg = _cfg([], device)
    sensor = make_sensor(cfg, "warp", device)
    seeds = [episode_seed(0, k) for k in range(batch)]
    t = {}
    t0 = time.perf_counter()
    protos = [make_episode_protocol(cfg, s) for s in seeds]
    n = protos[0].n_samples
    t["protocols"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    contact.episode_controls(cfg, protos, (n - 1) * cfg.sampling.substeps)
    t["controls (inside physics, on a thread)"] = time.perf_counter() - t0
    warm = contact.simulate_sensors(cfg, protos[:8])  # warm-up: compile, capture
    sensor.run_load(contact.load_batch(cfg, *warm, device_fields=device), seeds[:8])
    t0 = time.perf_counter()
    sens, target = contact.simulate_sensors(cfg, protos)
    t["physics (MuJoCo Warp)"] = time.perf_counter() - t0
    t["load field (Warp)"] = t["sensor chain (Warp)"] = t["channels"] = 0.0
    res = []
    for a in range(0, batch, SENSOR_SLICE):
        sl = slice(a, min(batch, a + SENSOR_SLICE))
        t0 = time.perf_counter()
        lb = contact.load_batch(cfg, sens[sl], target[sl], device_fields=device)
        t["load field (Warp)"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        out = sensor.run_load(lb, seeds[sl])
        t["sensor chain (Warp)"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        arrays = channel_arrays(lb, out, cfg, sensor)
        res += [EpisodeResult(f"ep-{a + j}", seeds[a + j], protos[a + j], episode_channels(arrays, j))
                for j in range(sl.stop - a)]
        t["channels"] += time.perf_counter() - t0
    nbytes = sum(c.data.nbytes for r in res for c in r.channels.values())
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_DIR")) as tmp:
        t0 = time.perf_counter()
        with RecordingWriter(Path(tmp) / "a.h5", source="sim", config_json="{}", root_seed=0, shard_index=0,
                             sensor_attrs={"family": "cnt_pdms"}, compression="none") as w:
            for k, r in enumerate(res):
                w.add_episode(r.ep_id, r.channels, _episode_attrs(r, k))
        t["hdf5 write"] = time.perf_counter() - t0
    samples = batch * n
    total = sum(v for k, v in t.items() if "inside" not in k)
    print(f"stages for {batch} episodes x {n} samples ({nbytes / samples:.0f} B/sample):")
    for k, v in t.items():
        print(f"  {k:40s} {v:7.3f} s  {v / total:5.1%}  ({samples / v:.3g} samples/s)")
    return {"episodes": batch, "samples": samples, "bytes_per_sample": nbytes / samples,
            "seconds": t, "serial_samples_per_s": samples / total}


def chain_profile(device: str, episodes: int) -> dict:
    """Seconds of each step of the sensor stage for one slice of `episodes` (synchronized after each), on
    a synthetic load: the per-taxel channel sum as C tile reductions vs the per-row kernel, the kernels,
    and the copies back."""
    import warp as wp

    from sensors import electronics as el
    from sensors.registry import make_sensor
    from sensors.cnt_pdms.kernels import TaxelChainWarp, drive_on_device, scaled_on_device
    from simulate.contact.load_field_kernels import load_field_warp

    cfg = _cfg([], device)
    s = make_sensor(cfg, "warp", device)
    T, N = 620, cfg.pad.n_taxels
    rng = np.random.default_rng(0)
    tt = np.arange(T) / 100.0
    depth = 1e-4 * np.sin(np.pi * tt)[None, :] * rng.uniform(0.5, 1.0, (episodes, 1))
    pos = np.stack([np.zeros((episodes, T)), np.zeros((episodes, T)), -depth], -1)
    force = np.stack([np.zeros((episodes, T)), np.zeros((episodes, T)), 5e4 * depth], -1)
    t: dict[str, float] = {}

    def step(name, fn):
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        r = fn()
        wp.synchronize_device(device)
        t[name] = t.get(name, 0.0) + time.perf_counter() - t0
        return r

    for rep in range(2):  # the first pass compiles; the second is timed
        t.clear()
        deform, _, _ = step("load field (upload + kernels)", lambda: load_field_warp(cfg, pos, force, device, to_host=False))
        d = step("drive (kernel)", lambda: drive_on_device(deform, cfg.pad.thickness_m))
        chain = step("taxel chain: set-up", lambda: TaxelChainWarp(s.tp, episodes, N, device))
        _, st_d, c_d = step("taxel chain: kernel", lambda: chain.run_device(d, T, s.mode))
        tc = np.arange(N)
        step("channel sum: C tile reductions per row", lambda: _tiled(el, c_d, st_d, tc, N, (episodes, T, N), device))
        g_d, _ = step("channel sum: per-row kernel", lambda: el.sum_channels_warp(c_d, st_d, tc, N, 1e-6, (episodes, T, N), device))
        e = cfg.sensor.electronics
        noise = el.NoiseSeeds(list(range(episodes)), e.white_noise_v, e.pink_noise_v)
        ro = step("readout (kernel + adc copy back)", lambda: el.readout_warp(g_d, (episodes, T, N), noise, s.ep, None, device, keep={"adc"}))
        step("force_taxel (kernel + copy back)", lambda: scaled_on_device(st_d, s.tp.taxel_area_m2).numpy())
        step("adc int32 -> int16 (host)", lambda: ro[0]["adc"].astype(np.int16))
    print(f"sensor stage, one slice of {episodes} episodes x {T} samples x {N} taxels:")
    for k, v in t.items():
        print(f"  {k:42s} {v:7.3f} s")
    return {"episodes": episodes, "samples": episodes * T, "seconds": dict(t)}


def _tiled(el, c_d, st_d, tc, N, shape, device):
    """The general channel sum (C tile reductions per row), forced for a per-taxel map."""
    import warp as wp

    E, T, _ = shape
    g = wp.empty(E * T * N, dtype=wp.float64, device=device)
    force = wp.empty(E * T, dtype=wp.float64, device=device)
    tcd = wp.array(np.asarray(tc, np.int32), dtype=wp.int32, device=device)
    wp.launch_tiled(el.sum_channels_kernel, dim=[E * T], inputs=[c_d, st_d, tcd, N, N, 1e-6, g, force],
                    block_dim=el.REDUCE_BLOCK if device.startswith("cuda") else 1, device=device)
    return g, force


def writer_vs_episode_length(lengths: list[int], total_samples: int) -> dict:
    """HDF5 writer alone (no physics): MB/s of the compact 36-taxel record against episode length, and the raw
    write of the same bytes to the same disk. The per-episode cost (groups, datasets, attributes) is fixed."""
    from sensors.data.recording import Channel, RecordingWriter

    rng = np.random.default_rng(0)
    out = {}
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_DIR")) as tmp:
        for T in lengths:
            ch = {"time": Channel(np.arange(T) / 100.0, "s", ("time",), "sample time"),
                  "target": Channel(rng.random(T).astype(np.float32), "m", ("time",), "target"),
                  "position": Channel(rng.random((T, 3)).astype(np.float32), "m", ("time", "xyz"), "position"),
                  "contact_force": Channel(rng.random((T, 3)).astype(np.float32), "N", ("time", "xyz"), "force"),
                  "force_taxel": Channel(rng.random((T, 36)).astype(np.float32), "N", ("time", "taxel"), "force"),
                  "adc": Channel(rng.integers(-8192, 8191, (T, 36)).astype(np.int16), "counts", ("time", "channel"), "adc")}
            n_ep = max(1, total_samples // T)
            nbytes = n_ep * sum(c.data.nbytes for c in ch.values())
            t0 = time.perf_counter()
            with RecordingWriter(Path(tmp) / f"w{T}.h5", source="sim", config_json="{}", root_seed=0, shard_index=0,
                                 sensor_attrs={"family": "cnt_pdms"}, compression="none") as w:
                for j in range(n_ep):
                    w.add_episode(f"ep-{j:06d}", ch, {"seed": j, "n_samples": T})
            dt = time.perf_counter() - t0
            raw = raw_write(Path(tmp), nbytes)
            out[T] = {"episodes": n_ep, "MB_per_s": nbytes / dt / 1e6, "raw_MB_per_s": raw,
                      "fraction_of_raw": nbytes / dt / 1e6 / raw, "ms_per_episode": 1e3 * dt / n_ep,
                      "samples_per_s": n_ep * T / dt}
            print(f"HDF5 writer, {T:6d}-sample episodes: {nbytes / dt / 1e6:7.0f} MB/s = {out[T]['fraction_of_raw']:.0%} of raw "
                  f"({raw:.0f} MB/s), {1e3 * dt / n_ep:.2f} ms/episode, {n_ep * T / dt:.3g} samples/s")
    return out


def raw_write(folder: Path, nbytes: int) -> float:
    """MB/s of writing nbytes to a plain file in 64 MiB blocks, fsync at the end."""
    block = np.random.default_rng(0).integers(0, 255, 64 * 2**20, dtype=np.uint8).tobytes()
    p = folder / "raw.bin"
    t0 = time.perf_counter()
    with open(p, "wb") as f:
        left = nbytes
        while left > 0:
            f.write(block[: min(left, len(block))])
            left -= len(block)
        f.flush()
        os.fsync(f.fileno())
    dt = time.perf_counter() - t0
    p.unlink()
    return nbytes / dt / 1e6


def run_samples(cfg, episodes: int) -> int:
    """Sensor samples of a run: the sum of each episode's own length (mixed frequencies: mixed lengths)."""
    from sensors.data.manifest import episode_seed
    from simulate.protocols.indenter import make_episode_protocol

    if len(set(cfg.protocol.frequencies_hz)) == 1:
        return episodes * make_episode_protocol(cfg, 0).n_samples
    return sum(make_episode_protocol(cfg, episode_seed(cfg.generation.root_seed, k)).n_samples for k in range(episodes))


def end_to_end(device: str, per_shard: int, workers: int, shards_per_worker: int, extra: list[str] | None = None) -> dict:
    """`workers` processes share the GPU(s), each writing `shards_per_worker` shards of `per_shard` episodes."""
    from simulate.generation.executors import generate

    episodes = per_shard * workers * shards_per_worker
    cfg = _cfg([f"generation.episodes={episodes}", f"generation.episodes_per_shard={per_shard}", *(extra or [])], device)
    root = Path(os.environ.get("BENCH_DIR", tempfile.gettempdir())) / f"e2e-{workers}"
    shutil.rmtree(root, ignore_errors=True)
    t0 = time.perf_counter()
    generate(cfg, root, executor="local", workers=workers, device=device)
    t_sync = time.perf_counter()
    os.sync()
    dt = time.perf_counter() - t0
    t_sync = time.perf_counter() - t_sync
    nbytes = sum(p.stat().st_size for p in root.glob("*.h5"))
    samples = run_samples(cfg, episodes)
    shutil.rmtree(root, ignore_errors=True)  # the disk holds the dataset or the raw file, not both
    root.mkdir(parents=True)
    raw = raw_write(root, nbytes)
    shutil.rmtree(root, ignore_errors=True)
    from simulate.generation.executors import _feed_by_default

    mode = "gpu feed (physics process, sensor chain here, writer processes)" if workers > 1 and _feed_by_default(cfg) else "shard workers"
    from simulate.generation.executors import LAST_GENERATE_SECONDS
    from simulate.generation.feed import LAST_RUN_SECONDS

    r = {"workers": workers, "mode": mode, "generate_seconds": dict(LAST_GENERATE_SECONDS),
         "driver_seconds": dict(LAST_RUN_SECONDS) if "feed" in mode else None, "episodes": episodes, "shards": -(-episodes // per_shard), "seconds": dt, "sync_seconds": t_sync,
         "samples_per_s": samples / dt, "disk_MB_per_s": nbytes / dt / 1e6, "raw_write_MB_per_s_same_bytes": raw,
         "fraction_of_raw_write": nbytes / dt / 1e6 / raw, "bytes": nbytes}
    if "feed" in mode:
        from simulate.generation import feed

        fw = feed.feed_worlds(cfg)
        r["feed_batches_episodes"] = [b["episodes"] for b in feed.LAST_RUN_BATCHES]
        r["feed_batches"] = [dict(b) for b in feed.LAST_RUN_BATCHES]  # in the order stepped (feed._schedule)
        r["feed_length_schedule"] = feed.LENGTH_SCHEDULE
        r["feed_worlds_per_batch"] = fw
    print(f"end to end, {workers} worker(s), {mode}, {episodes} episodes ({per_shard} per shard): {samples / dt:.3g} samples/s, "
          f"{nbytes / dt / 1e6:.0f} MB/s on disk = {r['fraction_of_raw_write']:.0%} of raw write ({raw:.0f} MB/s), incl. start-up; "
          f"generate: {', '.join(f'{k} {v:.1f} s' for k, v in LAST_GENERATE_SECONDS.items())}, sync {t_sync:.1f} s"
          + (f"; driver: {', '.join(f'{k} {v:.1f} s' for k, v in LAST_RUN_SECONDS.items())}" if "feed" in mode else ""))
    return r


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--worlds", default="1024,4096,16384")
    ap.add_argument("--physics-samples", type=int, default=101)
    ap.add_argument("--stage-batch", type=int, default=2048)
    ap.add_argument("--shard-episodes", type=int, default=8192)
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--shards-per-worker", type=int, default=1)
    ap.add_argument("--physics-processes", type=int, default=None, help="e2e: the GPU feed's physics processes")
    ap.add_argument("--ramp-batches", type=int, default=None, help="e2e: the GPU feed's RAMP_BATCHES (default: the module's)")
    ap.add_argument("--schedule", choices=["length", "shards"], default="length",
                    help="e2e: the GPU feed's batches: by episode length where lengths mix (feed._schedule, the default) "
                         "or whole shards (feed._groups, session 10)")
    ap.add_argument("--batch-ram-fraction", type=float, default=None, help="e2e: the GPU feed's BATCH_RAM_FRACTION")
    ap.add_argument("--override", action="append", default=[], help="e2e: a scene override on top of the bench scene")
    ap.add_argument("--parts", default="physics,equivalence,stages,e2e")
    ap.add_argument("--tag", default="", help="result file name: gpu-pipeline-<tag>.json")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()

    from sensors.warp_setup import init_warp

    init_warp()
    import warp as wp

    res: dict = {"host": platform.node(), "cpus": os.cpu_count(), "device": a.device,
                 "device_name": wp.get_device(a.device).name if a.device != "cpu" else platform.processor(),
                 "scene": {"preset": "cnt_pdms", "overrides": BASE}}
    parts = a.parts.split(",")
    if "physics" in parts:
        res["physics"] = physics(a.device, [int(w) for w in a.worlds.split(",")], a.physics_samples)
    if "multigpu" in parts:
        res["physics_multi_gpu"] = physics_multi_gpu(int(a.worlds.split(",")[-1]), a.physics_samples)
    if "equivalence" in parts:
        res["equivalence"] = equivalence(a.device)
    if "writer" in parts:
        res["writer"] = writer_vs_episode_length([620, 3020, 12000, 60000], 3_000_000)
    if "chain" in parts:
        res["chain_profile"] = chain_profile(a.device, a.stage_batch)
    if "stages" in parts:
        res["stages"] = stages(a.device, a.stage_batch)
    if "e2e" in parts:
        from simulate.generation.feed import FEED_WORLDS
        from simulate.generation.run import GPU_BATCH, SENSOR_SLICE

        res["gpu_batch"], res["feed_worlds"], res["sensor_slice"] = GPU_BATCH, FEED_WORLDS, SENSOR_SLICE
        from simulate.generation import feed

        if a.physics_processes:
            feed.PHYSICS_PROCESSES = a.physics_processes
        if a.ramp_batches is not None:
            feed.RAMP_BATCHES = a.ramp_batches
        if a.batch_ram_fraction is not None:
            feed.BATCH_RAM_FRACTION = a.batch_ram_fraction
        feed.LENGTH_SCHEDULE = a.schedule == "length"
        res["physics_processes"], res["e2e_overrides"] = feed.PHYSICS_PROCESSES, a.override
        res["ramp_batches"], res["batch_ram_fraction"] = feed.RAMP_BATCHES, feed.BATCH_RAM_FRACTION
        res["end_to_end"] = [end_to_end(a.device, a.shard_episodes, int(w), a.shards_per_worker, a.override) for w in a.workers.split(",")]
        r1 = res["end_to_end"][0]
        for r in res["end_to_end"]:
            r["scaling_efficiency_vs_first"] = r["samples_per_s"] / (r1["samples_per_s"] * r["workers"] / r1["workers"])
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"gpu-pipeline-{a.tag or ('gpu' if a.device != 'cpu' else 'cpu')}.json"
    path.write_text(json.dumps(res, indent=2, default=str))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

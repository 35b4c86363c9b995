"""The GPU feed's driver stage alone (load field, sensor chain, channel arrays, pack into shared blocks) on a batch
whose physics is made up, profiled: where the tail after the worlds' stepping goes (issue 16: fabric_1's single
batch spends 10.7 s in "simulate" and 2.7 s in "pack" on the H100 after 83 s of stepping, session 10).

    python bench/bench_feed_stage.py --family fabric_1 --episodes 8192 [--device cuda] [--tag h100-s11]

The sensordata block is made and filled by a spawned process, as the feed's physics process does (so this process
maps its pages on first touch, as the driver does); its values are the episodes' targets as the normal force and
small made-up pose / shear values, not physics: the stage's cost does not depend on them. `Producer.batch` then
runs as in `generate_feed`, with cProfile on. Writes bench/results/feed-stage-<family>-<tag>.json: seconds of the
feed's own split ("simulate", "pack") and the functions with the most time.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def _scene(family: str, device: str):
    from scenes import load_scene

    return load_scene(family, ["generation.physics=mujoco_warp", f"generation.device={device}"])


def made_up_physics(family: str, device: str, gids: list[int]) -> tuple[list, dict]:
    """In a spawned process: the episodes' protocols and {n_samples: (block name, layout)} like `step_worlds`."""
    from multiprocessing import shared_memory

    import numpy as np

    from sensors.data.manifest import episode_seed
    from simulate.contact import load_field as lf
    from simulate.generation.run import episode_protocols, length_groups

    cfg = _scene(family, device)
    protos = episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in gids], gids)
    m = lf.build_model(cfg)
    rng = np.random.default_rng(0)
    out = {}
    rows = 64  # made-up episodes repeated over the batch (cheap to make; the stage's cost does not depend on values)
    for n, idx in length_groups(protos):
        E = len(idx)
        target = lf.sample_targets(cfg, [protos[i] for i in idx], n)
        ns = len(lf.read_columns(m))  # what simulate_sensors keeps
        shm = shared_memory.SharedMemory(create=True, size=8 * (E * n * ns + E * n))
        sens = np.ndarray((E, n, ns), np.float64, buffer=shm.buf)
        block = np.zeros((min(E, rows), n, ns))
        block[..., lf._POS] = rng.normal(0.0, 1e-5, (len(block), n, 3))
        block[..., lf._FORCE] = np.stack([rng.normal(0, 0.01, (len(block), n)), rng.normal(0, 0.01, (len(block), n)),
                                          -np.abs(target[: len(block)])], -1)
        block[..., lf._FOUND] = 1.0
        for a in range(0, E, len(block)):
            sens[a : a + len(block)] = block[: E - a]
        np.ndarray(target.shape, np.float64, buffer=shm.buf, offset=sens.nbytes)[...] = target
        out[n] = (shm.name, [(0, sens.dtype.str, sens.shape), (sens.nbytes, "<f8", target.shape)])
        sens = None
        shm.close()
    return protos, out


def main() -> None:
    import cProfile
    import io
    import multiprocessing as mp
    import pstats
    from concurrent.futures import ProcessPoolExecutor

    ap = argparse.ArgumentParser()
    ap.add_argument("--family", default="fabric_1")
    ap.add_argument("--episodes", type=int, default=8192)
    ap.add_argument("--per-shard", type=int, default=8, help="episodes per shard (the preset's default for fabric_1)")
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--host-threads", default="", help="comma list: rerun the stage with load_field.HOST_PASS_THREADS "
                    "at each (the A/B of the threaded host passes), on fresh made-up physics each time")
    ap.add_argument("--pack-overlap", default="", help="comma list of 0 / 1: rerun the stage with feed.PACK_OVERLAP off / "
                    "on (the A/B of packing slice i while slice i + 1 runs; profiled: the first), fresh made-up physics each time")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--tag", default="local")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()

    from sensors.registry import make_sensor
    from sensors.warp_setup import init_warp
    from simulate.generation import feed

    from scenes import load_scene

    cfg = load_scene(a.family, ["generation.physics=mujoco_warp", f"generation.device={a.device}",
                                f"generation.episodes={a.episodes}", f"generation.episodes_per_shard={a.per_shard}"])
    init_warp()
    shards = list(range(-(-a.episodes // a.per_shard)))
    gids = list(range(a.episodes))
    t0 = time.perf_counter()
    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as ex:
        warm = ex.submit(made_up_physics, a.family, a.device, gids[: a.per_shard]).result()
        stepped = ex.submit(made_up_physics, a.family, a.device, gids).result()
    t_phys = time.perf_counter() - t0
    sensor = make_sensor(cfg, "warp", a.device)
    pool = feed.BlockPool()
    for p in feed.Producer(cfg, sensor, 1, {}, pool).batch(shards[:1], warm):  # imports, kernels loaded: not timed
        for name in p.block_names:
            pool.put(name)
    from simulate.contact import load_field as lf

    runs = []
    prof = cProfile.Profile()
    try:
        if a.pack_overlap:
            configs = [(lf.HOST_PASS_THREADS, bool(int(x))) for x in a.pack_overlap.split(",") if x]
        else:
            configs = [(int(x), feed.PACK_OVERLAP) for x in a.host_threads.split(",") if x] or [(lf.HOST_PASS_THREADS, feed.PACK_OVERLAP)]
        for i, (th, overlap) in enumerate(configs):
            feed.PACK_OVERLAP = overlap
            if i:  # fresh made-up physics: the stage unlinks its blocks
                with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as ex:
                    stepped = ex.submit(made_up_physics, a.family, a.device, gids).result()
            lf.HOST_PASS_THREADS, lf._HOST_PASSES = th, None
            seconds: dict = {}
            done = 0
            profile = i == 0 and not a.no_profile
            t0 = time.perf_counter()
            if profile:
                prof.enable()
            for p in feed.Producer(cfg, sensor, 1, seconds, pool).batch(shards, stepped):
                done += p.n_episodes
                for name in p.block_names:
                    pool.put(name)
            if profile:
                prof.disable()
            dt = time.perf_counter() - t0
            assert done == a.episodes
            runs.append({"host_pass_threads": th, "pack_overlap": overlap, "profiled": profile, "seconds": dt,
                         "feed_seconds": seconds})
            print(f"stage {dt:.2f} s{' (profiled)' if profile else ''} with {th} host-pass thread(s), pack overlap {overlap}: "
                  + ", ".join(f"{k} {v:.2f} s" for k, v in seconds.items()))
    finally:
        pool.close()
    seconds, dt = runs[0]["feed_seconds"], runs[0]["seconds"]
    top = []
    if runs[0]["profiled"]:
        s = io.StringIO()
        st = pstats.Stats(prof, stream=s)
        st.sort_stats("tottime").print_stats(25)
        st.sort_stats("cumulative").print_stats(40)
        print(s.getvalue())
        top = sorted(((v[2], v[3], f"{k[0].split('/')[-1]}:{k[1]}({k[2]})") for k, v in st.stats.items()), reverse=True)
    import warp as wp

    res = {"device": a.device, "device_name": wp.get_device(a.device).name, "family": a.family, "episodes": a.episodes,
           "samples": sum(p.n_samples for p in stepped[0]), "made_up_physics_seconds": t_phys,
           "stage_seconds_profiled": dt if runs[0]["profiled"] else None, "feed_seconds": seconds, "runs": runs,
           "top_tottime": [{"fn": f, "tottime_s": t, "cumtime_s": c} for t, c, f in top[:25]]}
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"feed-stage-{a.family}-{a.tag}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

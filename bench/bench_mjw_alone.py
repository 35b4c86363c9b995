"""MuJoCo Warp stepping the worlds of a `piezotwin generate` run alone: the bound of a physics-bound CLI run.

    python bench/bench_mjw_alone.py --family fabric_1 --episodes 8192 [--tag h100-s8] [--worlds 4096]

The scene, overrides and episodes are those of `piezotwin generate <family> --episodes N` with defaults (the
`auto` choice made the same way, so the same physics step), batched as the GPU feed batches them
(`simulate.generation.feed._groups`); each batch runs `step_worlds` (protocols, controls, MuJoCo Warp, sensordata
into shared memory) in this one process, one batch after another, with nothing else on the GPU. `--worlds N`: batches of N episodes instead
(no ramp), to price another split of the same run (e.g. its halves, stepped one after the other). A 64-world
batch of two samples first loads the kernels (compiled by the CLI run before, so the Warp cache is warm), not timed. Reported:
seconds per batch ("worlds": the MuJoCo Warp part, as the feed's timings name it; "wall": the whole task),
samples/s and world-steps/s. Merged into bench/results/user-cli-<tag>.json under runs.<family>.mjw_alone when
that file has the family's run (bench_user_cli.py writes it), else written to mjw-alone-<tag>-<family>.json.
ntype's press_stroke (its own contact stage): per feed batch (full, no ramp), its protocols, then
`press_stroke_physics` (MuJoCo Warp worlds with the stick-slip kernel), as the feed's physics processes run them.
"""

from __future__ import annotations

import argparse
import json
import time
from multiprocessing import shared_memory
from pathlib import Path


def _free(out: dict) -> None:
    for v in out.values():
        if isinstance(v[0], str):
            shm = shared_memory.SharedMemory(name=v[0])
            shm.close()
            shm.unlink()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--family", required=True)
    ap.add_argument("--episodes", type=int, required=True)
    ap.add_argument("--tag", default="local")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    ap.add_argument("--worlds", type=int, default=None,
                    help="batches of this many episodes, no ramp, instead of the feed's (e.g. a run's halves)")
    a = ap.parse_args()
    from scenes import load_scene
    from simulate.generation.choice import choose
    from simulate.generation.feed import _groups, feed_worlds, step_worlds
    from simulate.generation.run import episode_ids_of_shard, n_shards

    base = [f"generation.episodes={a.episodes}"]
    cfg = load_scene(a.family, base)
    chosen = choose(cfg)
    cfg = load_scene(a.family, base + chosen.overrides)
    print(chosen.line())
    from simulate.contact.load_field import CONTACT_STAGES

    stage = cfg.protocol.kind in CONTACT_STAGES  # ntype's press_stroke: full batches (no ramp), its own physics
    groups = (_groups(cfg, list(range(n_shards(cfg))), feed_worlds(cfg), ramp=0 if stage else None) if a.worlds is None
              else _groups(cfg, list(range(n_shards(cfg))), a.worlds, ramp=0))
    if stage:
        return _contact_stage_alone(a, cfg, chosen, groups)
    # load the kernels (Warp's cache is warm from the CLI run): 64 worlds of the same model, two samples
    import numpy as np

    from simulate.contact.load_field import build_model, physics_engine, read_columns
    from simulate.contact.mujoco_warp import WarpWorlds

    m = build_model(cfg)
    sub = cfg.sampling.substeps
    q0 = np.zeros((64, m.nq))
    q0[:, 2] = cfg.indenter.start_gap_m
    cols = read_columns(m)  # the columns step_worlds records (the same kernels)
    WarpWorlds(m, 64, physics_engine(cfg)[1], columns=cols).run(q0, np.zeros((64, 2 * sub, m.nu)), np.zeros(len(cols)), sub, 3)
    batches = []
    samples = 0
    steps = 0
    t0 = time.perf_counter()
    for g in groups:
        gids = [k for s in g for k in episode_ids_of_shard(cfg, s)]
        t1 = time.perf_counter()
        protos, out, spent = step_worlds(cfg, gids)
        wall = time.perf_counter() - t1
        _free(out)
        n = sum(p.n_samples for p in protos)
        samples += n
        steps += (max(p.n_samples for p in protos) - 1) * cfg.sampling.substeps
        batches.append({"episodes": len(gids), "samples": n, "wall_s": wall, "worlds_s": spent["worlds"],
                        "sequential_steps": (max(p.n_samples for p in protos) - 1) * cfg.sampling.substeps})
        print(f"batch of {len(gids)} episodes: {wall:.1f} s ({spent['worlds']:.1f} s worlds)")
    total = time.perf_counter() - t0
    res = {
        "engine_line": chosen.line(),
        "physics_timestep_s": cfg.sampling.physics_timestep_s,
        "episodes": a.episodes,
        "worlds_per_batch": a.worlds,  # None: the feed's batches
        "batches": batches,
        "seconds": total,
        "worlds_seconds": sum(b["worlds_s"] for b in batches),
        "samples": samples,
        "samples_per_s": samples / total,
        "world_steps_per_s": sum(b["episodes"] * b["sequential_steps"] for b in batches) / total,
    }
    _report(a, res)


def _contact_stage_alone(a, cfg, chosen, groups) -> None:
    """A kind with its own contact stage (ntype's press_stroke): per feed batch, its protocols, then its MuJoCo Warp
    worlds with the stick-slip kernel (`press_stroke_physics`, what the feed's physics processes run), nothing else."""
    from sensors.data.manifest import episode_seed
    from simulate.contact.press_stroke import press_stroke_physics
    from simulate.generation.run import episode_ids_of_shard, episode_protocols

    warm = episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in range(64)], list(range(64)))
    press_stroke_physics(cfg, warm)  # the kernels loaded (Warp's cache warm from the CLI run), not timed
    batches, samples = [], 0
    t0 = time.perf_counter()
    for g in groups:
        gids = [k for s in g for k in episode_ids_of_shard(cfg, s)]
        t1 = time.perf_counter()
        protos = episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in gids], gids)
        t2 = time.perf_counter()
        press_stroke_physics(cfg, protos)
        t3 = time.perf_counter()
        n = sum(p.n_samples for p in protos)
        samples += n
        steps = (protos[0].n_samples - 1) * cfg.sampling.substeps
        batches.append({"episodes": len(gids), "samples": n, "wall_s": t3 - t1, "protocols_s": t2 - t1, "worlds_s": t3 - t2,
                        "sequential_steps": steps})
        print(f"batch of {len(gids)} episodes: {t3 - t1:.1f} s ({t3 - t2:.1f} s worlds)")
    total = time.perf_counter() - t0
    _report(a, {"engine_line": chosen.line(), "physics_timestep_s": cfg.sampling.physics_timestep_s, "episodes": a.episodes,
                "worlds_per_batch": a.worlds, "batches": batches, "seconds": total,
                "worlds_seconds": sum(b["worlds_s"] for b in batches), "samples": samples, "samples_per_s": samples / total,
                "world_steps_per_s": sum(b["episodes"] * b["sequential_steps"] for b in batches) / total,
                "what": "protocols + MuJoCo Warp worlds with the stick-slip kernel, per feed batch (the driver's contact stage)"})


def _report(a, res: dict) -> None:
    print(f"{a.family}: {res['samples']} samples in {res['seconds']:.1f} s = {res['samples_per_s']:.3g} samples/s stepping alone")
    cli = a.out / f"user-cli-{a.tag}.json"
    if cli.exists() and a.family in (d := json.loads(cli.read_text()))["runs"]:
        d["runs"][a.family]["mjw_alone"] = res
        cli.write_text(json.dumps(d, indent=1) + "\n")
    else:
        (a.out / f"mjw-alone-{a.tag}-{a.family}.json").write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()

"""Where MuJoCo Warp's step time goes on the bench scene, and what skipping sensors between records buys.

    python bench/bench_physics_profile.py --device cuda:0 [--worlds 32768] [--samples 41]

Scene: the one of bench_gpu_pipeline.py (cnt_pdms, box indenter on a box pad, 10 x 1 ms steps per 100 Hz
sample). Measured in one run, written to bench/results/physics-profile-<tag>.json:
1. world-steps/s of `simulate.contact.mujoco_warp.WarpWorlds` (CUDA graph per sample period) with sensors computed in
   every step and with sensors only in the recorded step (the default), same worlds and controls;
2. GPU time per kernel over one sample period, launched eagerly (Warp's kernel timing: the sum of the kernels
   is the GPU work a graph replays, without the launch gaps), grouped by kernel name, largest first;
3. (--parts variants) solver and collision options of the same model: world-steps/s and how far the recorded
   contact force and position move from the default options' (same worlds and controls).
"""

from __future__ import annotations

import argparse
import json
import re
import time
from collections import defaultdict
from pathlib import Path

from bench_gpu_pipeline import _cfg


def _worlds(cfg, n_worlds: int, n_samples: int):
    from simulate.contact.load_field import _initial_states, build_model, episode_controls
    from simulate.protocols.indenter import make_episode_protocol

    m, sub = build_model(cfg), cfg.sampling.substeps
    protos = [make_episode_protocol(cfg, s) for s in range(n_worlds)]
    ctrl, _ = episode_controls(cfg, protos, (n_samples - 1) * sub)
    st, s0 = _initial_states(m, cfg, protos, ctrl[:, 0])
    return m, sub, st[:, 1 : 1 + m.nq], ctrl, s0


def rates(device: str, n_worlds: int, n_samples: int) -> dict:
    """world-steps/s with sensors in every step and only in the recorded one (each after a warm-up run)."""
    from simulate.contact.mujoco_warp import WarpWorlds

    m, sub, q0, ctrl, s0 = _worlds(_cfg([]), n_worlds, n_samples)
    out = {}
    for every in (True, False):
        ww = WarpWorlds(m, n_worlds, device, sensors_every_step=every)
        ww.run(q0, ctrl, s0, sub, n_samples)  # compile, capture
        t0 = time.perf_counter()
        ww.run(q0, ctrl, s0, sub, n_samples)
        dt = time.perf_counter() - t0
        name = "sensors every step" if every else "sensors in the recorded step"
        out[name] = {"seconds": dt, "world_steps_per_s": n_worlds * (n_samples - 1) * sub / dt}
        print(f"{name}: {out[name]['world_steps_per_s']:.3g} world-steps/s ({n_worlds} worlds)")
        del ww
    a, b = (out[k]["world_steps_per_s"] for k in ("sensors every step", "sensors in the recorded step"))
    out["speed-up"] = b / a
    return out


def kernel_profile(device: str, n_worlds: int, top: int = 30) -> dict:
    """GPU milliseconds per kernel name for one sample period (substeps steps + record) of n_worlds worlds."""
    import warp as wp

    from simulate.contact.mujoco_warp import WarpWorlds

    m, sub, q0, ctrl, s0 = _worlds(_cfg([]), n_worlds, 6)
    ww = WarpWorlds(m, n_worlds, device)
    ww.run(q0, ctrl, s0, sub, 6)  # leaves the worlds mid-episode, the indenter pressing
    first = ww._buffers[2][0]  # noqa: SLF001 - the bench drives one sample period by hand
    seq, rec = first.seq, first.rec
    with wp.ScopedDevice(device):
        ww.counter.zero_()
        ww._step_sample(seq, rec, sub)  # noqa: SLF001 - warm (eager launches)
        ww.counter.zero_()
        wp.synchronize_device(device)
        wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)
        t0 = time.perf_counter()
        ww._step_sample(seq, rec, sub)  # noqa: SLF001
        wp.synchronize_device(device)
        wall = time.perf_counter() - t0
        results = wp.timing_end()
    per = defaultdict(lambda: [0.0, 0])
    for r in results:
        name = re.sub(r"_[0-9a-f]{6,}$", "", r.name.split("::")[-1])
        per[name][0] += r.elapsed
        per[name][1] += 1
    total = sum(v[0] for v in per.values())
    rows = sorted(per.items(), key=lambda kv: -kv[1][0])
    print(f"one sample period ({sub} steps, {n_worlds} worlds): {len(results)} launches, {total:.2f} ms of kernels, "
          f"{wall * 1e3:.1f} ms wall (eager)")
    for name, (ms, n) in rows[:top]:
        print(f"  {ms:8.3f} ms {ms / total:6.1%} x{n:4d}  {name}")
    return {"worlds": n_worlds, "launches": len(results), "kernel_ms": total, "eager_wall_ms": wall * 1e3,
            "kernels": [{"name": k, "ms": v[0], "launches": v[1]} for k, v in rows[:top]]}


VARIANTS = {  # name -> (MjModel.opt changes, MuJoCo Warp-only Option changes)
    "default": ({}, {}),
    "ls_iterations=10": ({"ls_iterations": 10}, {}),
    "ls_iterations=4": ({"ls_iterations": 4}, {}),
    "ccd_iterations=12": ({"ccd_iterations": 12}, {}),
    "ls_iterations=10, ccd_iterations=12": ({"ls_iterations": 10, "ccd_iterations": 12}, {}),
    "run_qacc_smooth=False": ({}, {"run_qacc_smooth": False}),
}  # measured on Warp's CPU device and left out: solver=CG (force 0.7 % of full scale off), mjDSBL_GRAVITY (0.15 %)


def variants(device: str, n_worlds: int, n_samples: int) -> dict:
    """world-steps/s of each VARIANTS entry and its largest deviation from the default options' sensordata."""
    import copy

    from simulate.contact.mujoco_warp import WarpWorlds

    m0, sub, q0, ctrl, s0 = _worlds(_cfg([]), n_worlds, n_samples)
    out, ref = {}, None
    for name, (opt, warp_opt) in VARIANTS.items():
        m = copy.copy(m0)
        for k, v in opt.items():
            setattr(m.opt, k, v)
        ww = WarpWorlds(m, n_worlds, device)
        for k, v in warp_opt.items():
            setattr(ww.m.opt, k, v)
            setattr(ww.m_quiet.opt, k, v)
        ww.run(q0, ctrl, s0, sub, n_samples)  # compile, capture
        t0 = time.perf_counter()
        sens = ww.run(q0, ctrl, s0, sub, n_samples)
        dt = time.perf_counter() - t0
        ref = sens if ref is None else ref
        full = float(abs(ref[..., 4:7]).max())
        r = {"world_steps_per_s": n_worlds * (n_samples - 1) * sub / dt,
             "max_force_dev_of_full_scale": float(abs(sens[..., 4:7] - ref[..., 4:7]).max()) / full,
             "max_position_dev_m": float(abs(sens[..., 0:3] - ref[..., 0:3]).max())}
        out[name] = r
        print(f"{name:40s} {r['world_steps_per_s']:.3g} world-steps/s, force dev {r['max_force_dev_of_full_scale']:.2e} of full "
              f"scale, position dev {r['max_position_dev_m']:.2e} m")
        del ww
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--worlds", type=int, default=32768)
    ap.add_argument("--samples", type=int, default=41)
    ap.add_argument("--tag", default="gpu")
    ap.add_argument("--parts", default="rates,kernels")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    from sensors.warp_setup import init_warp

    init_warp()
    import warp as wp

    res = {"device": a.device, "device_name": wp.get_device(a.device).name, "worlds": a.worlds, "samples": a.samples}
    parts = a.parts.split(",")
    if "rates" in parts:
        res["rates"] = rates(a.device, a.worlds, a.samples)
    if "kernels" in parts:
        res["kernels"] = kernel_profile(a.device, a.worlds)
    if "variants" in parts:
        res["variants"] = variants(a.device, a.worlds, a.samples)
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"physics-profile-{a.tag}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

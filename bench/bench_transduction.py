"""Transduction chain speed: Warp (CPU, and CUDA when present) vs the numpy reference, in one run.

Measures taxel-steps/s of the per-taxel kernel alone and of the whole chain (taxel kernel + channel sums +
bridge/ADC/filter readout) on E episodes x (side x side) taxels x T steps, with the drive already on the
device (host transfers are reported apart). Writes bench/results/transduction-<host>.json and prints ratios.

    python bench/bench_transduction.py                       # CPU: numpy vs Warp
    python bench/bench_transduction.py --gpu-episodes 256    # adds CUDA at the issue's size (256 x 64 x 64 x 1000)
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np


def _drive(E: int, T: int, N: int) -> np.ndarray:
    t = np.arange(T, dtype=np.float32) / 100.0
    amp = np.random.default_rng(0).uniform(0.005, 0.04, (E, 1, N)).astype(np.float32)
    return (amp * (0.5 - 0.5 * np.cos(2 * np.pi * 1.0 * t))[None, :, None]).astype(np.float32)


def bench_numpy(cfg, E, T, N):
    from sensors.cnt_pdms.params import taxel_params
    from sensors.cnt_pdms.reference import taxel_chain_numpy

    d = _drive(E, T, N)
    t0 = time.perf_counter()
    taxel_chain_numpy(d, 0, taxel_params(cfg))
    return E * T * N / (time.perf_counter() - t0)


def bench_warp(cfg, E, T, N, device, repeats=3):
    import warp as wp

    from sensors import electronics as el
    from sensors.cnt_pdms.params import electronics_params, taxel_params
    from sensors.cnt_pdms.kernels import TaxelChainWarp

    tp, ep = taxel_params(cfg), electronics_params(cfg)
    chain = TaxelChainWarp(tp, E, N, device)
    host = _drive(E, T, N).reshape(-1)
    t0 = time.perf_counter()
    drive = wp.array(host, dtype=wp.float32, device=chain.device)
    wp.synchronize_device(chain.device)
    h2d = time.perf_counter() - t0
    outs = [wp.empty(E * T * N, dtype=wp.float32, device=chain.device) for _ in range(3)]
    chain.run_device(drive, T, 0, outs)  # warm-up / compile
    wp.synchronize_device(chain.device)
    best = float("inf")
    for _ in range(repeats):
        chain.reset()
        t0 = time.perf_counter()
        chain.run_device(drive, T, 0, outs)
        wp.synchronize_device(chain.device)
        best = min(best, time.perf_counter() - t0)
    noise = np.zeros((E, T, 1))
    tc = np.zeros(N, np.int32)

    def whole_chain():
        chain.run_device(drive, T, 0, outs)
        g, _ = el.sum_channels_warp(outs[2], outs[1], tc, 1, tp.taxel_area_m2, (E, T, N), chain.device)
        el.readout_warp(g, (E, T, 1), noise, ep, None, chain.device)

    whole_chain()  # compile
    best_full = float("inf")
    for _ in range(repeats):
        chain.reset()
        wp.synchronize_device(chain.device)
        t0 = time.perf_counter()
        whole_chain()
        wp.synchronize_device(chain.device)
        best_full = min(best_full, time.perf_counter() - t0)
    # where the whole chain's time goes: each stage alone, synchronised between stages (best of `repeats`)
    stage_s = {"taxel kernel": float("inf"), "channel sums": float("inf"), "readout + copies back": float("inf")}
    for _ in range(repeats):
        chain.reset()
        wp.synchronize_device(chain.device)
        t0 = time.perf_counter()
        chain.run_device(drive, T, 0, outs)
        wp.synchronize_device(chain.device)
        t1 = time.perf_counter()
        g, _ = el.sum_channels_warp(outs[2], outs[1], tc, 1, tp.taxel_area_m2, (E, T, N), chain.device)
        wp.synchronize_device(chain.device)
        t2 = time.perf_counter()
        el.readout_warp(g, (E, T, 1), noise, ep, None, chain.device)
        wp.synchronize_device(chain.device)
        t3 = time.perf_counter()
        for k, v in zip(stage_s, (t1 - t0, t2 - t1, t3 - t2)):
            stage_s[k] = min(stage_s[k], v)
    return {"kernel": E * T * N / best, "chain": E * T * N / best_full, "h2d_s": h2d, "device": chain.device,
            "chain_seconds": best_full, "stage_seconds": stage_s}


def bench_fabric(E: int, T: int, N: int, device: str = "cpu", repeats: int = 7) -> dict:
    """fabric_1 kernel with the per-press area and knit set (issue 13) and without (the chain before), same run."""
    from dataclasses import replace

    import warp as wp

    from scenes import load_scene
    from sensors.fabric.kernels import FabricChainWarp
    from sensors.fabric.reference import fabric_params, press_draws

    p = replace(fabric_params(load_scene("fabric_1")), n_taxels=N)
    t = np.arange(T, dtype=np.float32) / 10.0
    amp = np.random.default_rng(0).uniform(0.5, 2.0, (E, 1, N)).astype(np.float32)
    drive = np.clip(amp * np.sin(2 * np.pi * 0.05 * t)[None, :, None], 0.0, None).astype(np.float32)  # presses
    chains = {}
    for name, press in (("before", False), ("after", True)):
        ch = FabricChainWarp(p, E, N, device, with_press=press)
        ch.set_draws(press_draws(list(range(E)), p))
        ch.run(drive)  # compile
        chains[name] = ch
    best = {name: float("inf") for name in chains}
    for _ in range(repeats):  # interleaved, best of each: a shared machine's load hits both alike
        for name, ch in chains.items():
            ch.reset()
            wp.synchronize_device(ch.device)
            t0 = time.perf_counter()
            ch.run(drive)
            wp.synchronize_device(ch.device)
            best[name] = min(best[name], time.perf_counter() - t0)
    out = {name: E * T * N / b for name, b in best.items()}
    out["cost_after_over_before"] = out["before"] / out["after"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=16, help="CPU batch (the numpy reference runs on the same)")
    ap.add_argument("--side", type=int, default=64)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--gpu-episodes", type=int, default=256)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    ap.add_argument("--tag", default="", help="result file name: transduction-<tag>.json (default gpu / cpu)")
    a = ap.parse_args()

    from scenes import load_scene
    from sensors.warp_setup import init_warp

    init_warp()
    import warp as wp

    cfg = load_scene("cnt_pdms")
    N = a.side * a.side
    res: dict = {"host": platform.node(), "cpu": platform.processor() or platform.machine(), "taxels": N, "steps": a.steps}
    res["numpy_ref"] = {"episodes": a.episodes, "taxel_steps_per_s": bench_numpy(cfg, a.episodes, a.steps, N)}
    w = bench_warp(cfg, a.episodes, a.steps, N, "cpu")
    res["warp_cpu"] = {"episodes": a.episodes, "taxel_steps_per_s_kernel": w["kernel"], "taxel_steps_per_s_chain": w["chain"]}
    print(f"numpy reference : {res['numpy_ref']['taxel_steps_per_s']:.3g} taxel-steps/s  ({a.episodes} x {N} x {a.steps})")
    print(f"warp cpu        : kernel {w['kernel']:.3g}, whole chain {w['chain']:.3g} taxel-steps/s")
    print(f"  ratio warp-cpu / numpy: {w['chain'] / res['numpy_ref']['taxel_steps_per_s']:.2f}x")
    if wp.get_cuda_device_count() > 0:
        g = bench_warp(cfg, a.gpu_episodes, a.steps, N, "cuda:0")
        res["warp_cuda"] = {
            "episodes": a.gpu_episodes, "device_name": wp.get_device("cuda:0").name,
            "taxel_steps_per_s_kernel": g["kernel"], "taxel_steps_per_s_chain": g["chain"], "h2d_s": g["h2d_s"],
            "chain_seconds": g["chain_seconds"], "stage_seconds": g["stage_seconds"],
        }
        print(f"warp cuda ({res['warp_cuda']['device_name']}): kernel {g['kernel']:.3g}, whole chain {g['chain']:.3g} "
              f"taxel-steps/s ({a.gpu_episodes} x {N} x {a.steps}); h2d of the drive {g['h2d_s']:.2f} s")
        print("  stages alone: " + ", ".join(f"{k} {1e3 * v:.2f} ms" for k, v in g["stage_seconds"].items())
              + f"; whole chain {1e3 * g['chain_seconds']:.2f} ms")
        print(f"  ratio cuda / warp-cpu: {g['chain'] / w['chain']:.0f}x; cuda / numpy: {g['chain'] / res['numpy_ref']['taxel_steps_per_s']:.0f}x")
    fe = min(a.episodes, 4)
    fb = bench_fabric(fe, a.steps, N, "cpu")
    res["fabric_warp_cpu"] = {"episodes": fe, "taxel_steps_per_s_before": fb["before"], "taxel_steps_per_s_after": fb["after"],
                              "cost_after_over_before": fb["cost_after_over_before"]}
    print(f"fabric warp cpu : {fb['before']:.3g} taxel-steps/s without the press state, {fb['after']:.3g} with "
          f"(cost {fb['cost_after_over_before']:.2f}x; issue 13 allows 1.5x)")
    if wp.get_cuda_device_count() > 0:
        fg = bench_fabric(a.gpu_episodes, a.steps, N, "cuda:0")
        res["fabric_warp_cuda"] = {"episodes": a.gpu_episodes, "taxel_steps_per_s_before": fg["before"],
                                   "taxel_steps_per_s_after": fg["after"], "cost_after_over_before": fg["cost_after_over_before"]}
        print(f"fabric warp cuda: cost of the press state {fg['cost_after_over_before']:.2f}x")
    a.out.mkdir(parents=True, exist_ok=True)
    tag = a.tag or ("gpu" if "warp_cuda" in res else "cpu")
    path = a.out / f"transduction-{tag}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

"""The fused pad-sum taxel kernel on CUDA with the step's divisions and exp exact (IEEE float32) against CUDA's
approximate instructions (`sensors.cnt_pdms.kernels.APPROX_MATH`: __fdividef, __expf; issue 16, session 13):
256 episodes x 4096 taxels x 1000 steps (the bench_transduction.py shape), strain + stress stored, best of 7, runs
interleaved, both load modes (0 displacement, 1 force); and how far the approximate outputs lie from the exact ones
(max relative difference of strain, stress, pad conductance, force). `PYTHONPATH=. python bench/fused_math.py
[--out FILE]`."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--episodes", type=int, default=256)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--taxels", type=int, default=4096)
    a = ap.parse_args()
    import warp as wp

    from scenes import load_scene
    from sensors.cnt_pdms.kernels import PREFETCH, WARP_LANES, TaxelChainWarp, taxel_sum_kernel
    from sensors.cnt_pdms.params import taxel_params
    from sensors.warp_setup import init_warp

    init_warp()
    d = a.device
    tp = taxel_params(load_scene("cnt_pdms"))
    E, T, N = a.episodes, a.steps, a.taxels
    group = WARP_LANES if wp.get_device(d).is_cuda else 1
    n_pad = -(-N // group) * group
    t = np.arange(T, dtype=np.float32) / 100.0
    amp = np.random.default_rng(0).uniform(0.005, 0.04, (E, 1, N)).astype(np.float32)
    shape = (amp * (0.5 - 0.5 * np.cos(2 * np.pi * t))[None, :, None]).reshape(-1)
    res = {"device_name": wp.get_device(d).name, "episodes": E, "taxels": N, "steps": T, "prefetch_depth": PREFETCH,
           "seconds": {}, "max_rel_diff_approx_vs_exact": {}}
    for mode, scale in ((0, 1.0), (1, 2e6)):  # strain drive; stress drive (Pa)
        drive = wp.array(shape * np.float32(scale), dtype=wp.float32, device=d)
        ch = TaxelChainWarp(tp, E, N, d)
        outs = {ap_: [wp.empty(E * T * N, dtype=wp.float32, device=d) for _ in range(2)]
                + [wp.empty(E * (n_pad // group) * T, dtype=wp.float64, device=d) for _ in range(2)] for ap_ in (False, True)}

        def run(approx: bool) -> None:
            k = taxel_sum_kernel(tp.n_prony, tp.n_play, PREFETCH, True, True, approx)
            o = outs[approx]
            wp.launch(k, dim=E * n_pad, inputs=[drive, T, N, n_pad, group, mode, ch.params, *ch._state_args(), 1, 1,
                                                o[0], o[1], o[2], o[3]], device=d)

        best = {False: float("inf"), True: float("inf")}
        for approx in (False, True):  # compile + first run
            ch.reset()
            run(approx)
        wp.synchronize_device(d)
        for _ in range(7):
            for approx in (False, True):
                ch.reset()
                wp.synchronize_device(d)
                t0 = time.perf_counter()
                run(approx)
                wp.synchronize_device(d)
                best[approx] = min(best[approx], time.perf_counter() - t0)
        for approx in (False, True):  # outputs from the reset state
            ch.reset()
            run(approx)
        wp.synchronize_device(d)
        diffs = {}
        for i, name in enumerate(("strain", "stress", "part_g", "part_f")):
            x, y = outs[False][i].numpy().astype(np.float64), outs[True][i].numpy().astype(np.float64)
            if name.startswith("part_"):  # the pad's per-step sums: add the partials of each (episode, step)
                x = x.reshape(E, -1, T).sum(1)
                y = y.reshape(E, -1, T).sum(1)
            scale_ = max(float(np.abs(x).max()), 1e-300)
            diffs[{"part_g": "pad conductance", "part_f": "pad stress sum"}.get(name, name)] = {
                "max_rel": float(np.max(np.abs(y - x) / np.maximum(np.abs(x), 1e-6 * scale_))),
                "max_abs_over_max": float(np.abs(y - x).max() / scale_)}
        key = f"mode {mode}"
        res["seconds"][key] = {"exact": best[False], "approx": best[True]}
        res["max_rel_diff_approx_vs_exact"][key] = diffs
        print(f"{key}: fused kernel exact {1e3 * best[False]:.2f} ms, approx {1e3 * best[True]:.2f} ms; "
              + ", ".join(f"{k} max rel {v['max_rel']:.2g}" for k, v in diffs.items()), flush=True)
    if a.out:
        a.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()

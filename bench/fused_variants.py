"""Timing of variants of the fused pad-sum taxel kernel on CUDA (issue 16, session 7: where its per-taxel stores
lose time): group sums (warp shuffles) on / off, partial-sum stores on / off, per-taxel strain + stress stores
on / off, against the plain kernel, 256 episodes x 4096 taxels x 1000 steps, best of 5, one process.
`PYTHONPATH=. python bench/fused_variants.py [--out FILE]`. Variants with sums or stores off give wrong sums:
timing only."""

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
    a = ap.parse_args()
    import warp as wp

    from scenes import load_scene
    from sensors.cnt_pdms.kernels import WARP_LANES, TaxelChainWarp, taxel_sum_kernel
    from sensors.cnt_pdms.params import taxel_params
    from sensors.warp_setup import init_warp

    init_warp()
    d = "cuda:0"
    tp = taxel_params(load_scene("cnt_pdms"))
    E, T, N = a.episodes, 1000, 4096
    t = np.arange(T, dtype=np.float32) / 100.0
    amp = np.random.default_rng(0).uniform(0.005, 0.04, (E, 1, N)).astype(np.float32)
    drive = wp.array((amp * (0.5 - 0.5 * np.cos(2 * np.pi * t))[None, :, None]).reshape(-1), dtype=wp.float32, device=d)
    ch = TaxelChainWarp(tp, E, N, d)
    outs = [wp.empty(E * T * N, dtype=wp.float32, device=d) for _ in range(3)]
    P = N // WARP_LANES
    pg, pf = (wp.empty(E * P * T, dtype=wp.float64, device=d) for _ in range(2))
    empty = wp.empty(0, dtype=wp.float32, device=d)

    def best(fn, n=5):
        fn()
        wp.synchronize_device(d)
        b = float("inf")
        for _ in range(n):
            ch.reset()
            wp.synchronize_device(d)
            t0 = time.perf_counter()
            fn()
            wp.synchronize_device(d)
            b = min(b, time.perf_counter() - t0)
        return b

    res = {"device_name": wp.get_device(d).name, "episodes": E, "taxels": N, "steps": T, "seconds": {}}
    res["seconds"]["plain kernel (strain, stress, conductance stored)"] = best(lambda: ch.run_device(drive, T, 0, outs))
    for depth in (0, 1):
        for shuffle in (True, False):
            for parts in (True, False):
                k = taxel_sum_kernel(tp.n_prony, tp.n_play, depth, shuffle, parts)
                for writes in (True, False):
                    def run(k=k, writes=writes):
                        wp.launch(k, dim=E * N, inputs=[drive, T, N, N, WARP_LANES, 0, ch.params, *ch._state_args(), int(writes),
                                                        int(writes), outs[0] if writes else empty, outs[1] if writes else empty, pg, pf], device=d)
                    name = f"fused, prefetch {depth}, shuffles {'on' if shuffle else 'off'}, partial stores {'on' if parts else 'off'}, strain + stress stores {'on' if writes else 'off'}"
                    res["seconds"][name] = best(run)
                    print(f"{name}: {1e3 * res['seconds'][name]:.2f} ms", flush=True)
    print(f"plain: {1e3 * res['seconds']['plain kernel (strain, stress, conductance stored)']:.2f} ms")
    if a.out:
        a.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()

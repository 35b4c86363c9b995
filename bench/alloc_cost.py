"""What a fresh device array costs on CUDA through Warp (issue 16, session 7): the memory pool's state, and the
wall time of allocating two 1 GiB float32 arrays, writing them with a trivial kernel, and dropping them,
against the same kernel on kept arrays. `PYTHONPATH=. python bench/alloc_cost.py [--out FILE]`."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import warp as wp


@wp.kernel
def _fill(a: wp.array(dtype=wp.float32), b: wp.array(dtype=wp.float32)):
    i = wp.tid()
    a[i] = 1.0
    b[i] = 2.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    from sensors.warp_setup import init_warp

    init_warp()
    d = "cuda:0"
    n = 1 << 28
    res = {"device_name": wp.get_device(d).name, "mempool_enabled": wp.is_mempool_enabled(d),
           "release_threshold_bytes": wp.get_mempool_release_threshold(d)}
    keep = [wp.empty(n, dtype=wp.float32, device=d) for _ in range(2)]
    for name, fresh in (("kept arrays", False), ("fresh arrays", True), ("kept arrays again", False)):
        best = float("inf")
        for _ in range(5):
            wp.synchronize_device(d)
            t0 = time.perf_counter()
            x = [wp.empty(n, dtype=wp.float32, device=d) for _ in range(2)] if fresh else keep
            wp.launch(_fill, dim=n, inputs=x, device=d)
            wp.synchronize_device(d)
            x = None
            wp.synchronize_device(d)
            best = min(best, time.perf_counter() - t0)
        res[f"{name}: fill 2 x 1 GiB, s"] = best
        print(f"{name}: {1e3 * best:.2f} ms", flush=True)
    print(res)
    if a.out:
        a.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()

"""Registers and local (spill) memory per thread of the cnt_pdms taxel kernels on a CUDA device, read from the
driver (cuFuncGetAttribute) after one launch of each: the plain chain and the fused pad-sum chain per prefetch
depth. `PYTHONPATH=. python bench/kernel_resources.py [--out FILE]` (issue 16, session 7: why the fused kernel's
per-taxel stores ran slow)."""

from __future__ import annotations

import argparse
import ctypes
import json
from pathlib import Path

import numpy as np


def func_attrs(handle) -> dict:
    cuda = ctypes.CDLL("libcuda.so.1")
    out = {}
    for name, attr in (("registers", 4), ("local_bytes", 3), ("max_threads_per_block", 0), ("const_bytes", 2)):
        v = ctypes.c_int(0)
        rc = cuda.cuFuncGetAttribute(ctypes.byref(v), attr, ctypes.c_void_p(handle))
        out[name] = v.value if rc == 0 else f"error {rc}"
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    import warp as wp

    from scenes import load_scene
    from sensors.cnt_pdms.kernels import TaxelChainWarp, taxel_kernels, taxel_sum_kernel
    from sensors.cnt_pdms.params import taxel_params
    from sensors.warp_setup import init_warp

    init_warp()
    dev = wp.get_device("cuda:0")
    tp = taxel_params(load_scene("cnt_pdms"))
    E, T, N = 2, 64, 64
    drive = wp.array(np.zeros(E * T * N, np.float32), device="cuda:0")
    res = {"device_name": dev.name}
    ch = TaxelChainWarp(tp, E, N, "cuda:0")
    ch.run_device(drive, T, 0)
    k = taxel_kernels(tp.n_prony, tp.n_play)["chain"]
    res["plain chain"] = func_attrs(k.module.get_kernel_hooks(k, dev).forward)
    for depth in (0, 1, 2, 4):
        ch.run_pad_device(drive, T, 0, tp.taxel_area_m2, depth=depth)
        kf = taxel_sum_kernel(tp.n_prony, tp.n_play, depth)
        res[f"fused, prefetch {depth}"] = func_attrs(kf.module.get_kernel_hooks(kf, dev).forward)
    res["block_dim"] = "Warp's default launch (256)"
    for name, r in res.items():
        print(name, r)
    if a.out:
        a.out.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()

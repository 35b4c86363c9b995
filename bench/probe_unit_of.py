"""Probe (session 27): the cost of VelostatSensor.unit_of on one feed slice's contact centroids (E x T x 2
float32), read from a page-locked host buffer (as the GPU feed hands them over: `sensors.warp_setup.to_host`) and
from ordinary memory, alone and while threads keep the interpreter busy. `python bench/probe_unit_of.py`"""

from __future__ import annotations

import threading
import time

import numpy as np
import warp as wp

from scenes import load_scene
from sensors.registry import make_sensor


def main() -> None:
    wp.init()
    cfg = load_scene("velostat")
    s = make_sensor(cfg, "numpy", "cpu")
    E, T = 1820, 1505
    rng = np.random.default_rng(0)
    host = rng.uniform(-0.05, 0.05, (E, T, 3)).astype(np.float32)
    host[:, :300, 1:] = np.nan
    cases = {"ordinary memory": host}
    if wp.is_cuda_available():
        pinned = wp.empty(shape=host.shape, dtype=wp.float32, device="cpu", pinned=True)
        pinned.numpy()[...] = host
        cases["page-locked (warp pinned=True)"] = pinned.numpy()
    stop = threading.Event()

    def busy() -> None:  # a Python thread that wants the interpreter (the feed's result / queue threads)
        x = 0
        while not stop.is_set():
            x += 1

    for label, arr in cases.items():
        for load in ("alone", "with 2 busy Python threads"):
            th = [threading.Thread(target=busy) for _ in range(2 if load != "alone" else 0)]
            for t in th:
                t.start()
            t0 = time.perf_counter()
            u = s.unit_of(arr[..., 1:])
            a = arr[..., 0].astype(np.float32)
            dt = time.perf_counter() - t0
            stop.set()
            for t in th:
                t.join()
            stop.clear()
            print(f"{label:32s} {load:28s} unit_of + force astype: {dt:.3f} s ({int((u >= 0).sum())} in contact)", flush=True)


if __name__ == "__main__":
    main()

"""What the HDF5 filter pipeline costs a writer per velostat episode (issue 16, session 16: velostat's GPU feed is bound
by its writers, ~220 MB/s of raw taxel fields per writer process): the preset's episodes written as plain chunked
datasets (chunks as `sensors.data.recording._chunk_len` makes them) with Blosc2 lz4 + shuffle + Fletcher-32 (the GPU
feed's default), and with one part changed or left out, down to no compression at all. CPU seconds per episode
(best of 3, 12 episodes a file) and bytes per episode on disk. `PYTHONPATH=. python bench/bench_writer_filters.py
[--family velostat] [--out FILE]`."""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import h5py
import hdf5plugin
import numpy as np

from scenes.loader import load_scene
from sensors.data.manifest import episode_seed
from sensors.data.recording import _chunk_len
from simulate.generation import run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--family", default="velostat")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    cfg = load_scene(a.family, ["generation.episodes=4"])
    sensor = run.make_sensor(cfg, "warp", "cpu")
    seeds = [episode_seed(0, k) for k in range(4)]
    eps = [r.channels for r in run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in range(4)], sensor,
                                                     indices=list(range(4)))]
    blosc = lambda cname, clevel, filt: dict(hdf5plugin.Blosc2(cname=cname, clevel=clevel, filters=filt))
    variants = {
        "lz4 + shuffle + fletcher32 (default)": {**blosc("lz4", 1, hdf5plugin.Blosc2.SHUFFLE), "fletcher32": True},
        "lz4 + shuffle": blosc("lz4", 1, hdf5plugin.Blosc2.SHUFFLE),
        "lz4 + fletcher32, no shuffle": {**blosc("lz4", 1, hdf5plugin.Blosc2.NOFILTER), "fletcher32": True},
        "lz4 + bitshuffle + fletcher32": {**blosc("lz4", 1, hdf5plugin.Blosc2.BITSHUFFLE), "fletcher32": True},
        "blosclz + shuffle + fletcher32": {**blosc("blosclz", 1, hdf5plugin.Blosc2.SHUFFLE), "fletcher32": True},
        "fletcher32 only (no compression)": {"fletcher32": True},
        "nothing (chunked, no filter)": {},
    }
    raw = float(np.mean([sum(c.data.nbytes for c in ep.values()) for ep in eps]))  # the 12 written cycle the 4
    out = {"family": a.family, "host": platform.node(), "cpus": os.cpu_count(), "raw_bytes_per_episode": raw,
           "episodes_per_file": 12, "variants": {}}
    d = tempfile.mkdtemp()
    for name, kw in variants.items():
        best, size = 1e9, 0.0
        for rep in range(3):
            p = os.path.join(d, f"v{rep}.h5")
            with h5py.File(p, "w") as f:
                t = time.process_time()
                for k in range(12):
                    g = f.create_group(f"e{k}")
                    for n, c in eps[k % 4].items():
                        x = c.data
                        if x.ndim >= 1 and x.size:
                            frame = int(np.prod(x.shape[1:])) * x.dtype.itemsize
                            g.create_dataset(n, data=x, chunks=(_chunk_len(x.shape[0], frame),) + x.shape[1:], **kw)
                        else:
                            g.create_dataset(n, data=x)
                best = min(best, (time.process_time() - t) / 12)
            size = os.path.getsize(p) / 12
            os.remove(p)
        out["variants"][name] = {"cpu_ms_per_episode": best * 1e3, "bytes_per_episode": size,
                                 "raw_MB_per_cpu_s": raw / best / 1e6}
        print(f"{name:36s} {best * 1e3:6.2f} ms/episode {size / 1e3:8.1f} kB/episode {raw / best / 1e6:6.0f} MB/s raw")
    if a.out:
        a.out.write_text(json.dumps(out, indent=1))
        print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

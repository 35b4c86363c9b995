"""The writers' cost per episode of each family's default preset, per compression: what the GPU feed's writers pay.

    python bench/bench_writer_codec.py [--families cnt_pdms,fabric_1,velostat,ntype] [--repeats 3] [--tag cpu]

One episode of each preset (C MuJoCo, numpy sensor chain; cnt_pdms at 2 Hz to keep it short) is written episode
by episode as a shard writer does (`RecordingWriter.add_episode`, 8 copies under new ids, so the cached template
path runs) with lzf (the CPU path's default), lz4 and zstd (Blosc2, level 1 + shuffle, through hdf5plugin); best of
`repeats` for each, interleaved. Reported per family and codec: seconds per episode, bytes per episode, chunks per
episode (Blosc2 pays a fixed cost per chunk, and a narrow frame of 1-36 values makes 1-40 KB chunks). Writes
bench/results/writer-codec-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

CODECS = ("lzf", "lz4", "zstd")
COPIES = 8


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--families", default="cnt_pdms,fabric_1,velostat,ntype")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", default="cpu")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    import h5py

    from scenes import load_scene
    from sensors.data.recording import RecordingWriter
    from sensors.registry import make_sensor
    from simulate.generation.run import _episode_attrs, simulate_episodes

    res = {"host": platform.node(), "cpus": os.cpu_count(), "copies": COPIES, "families": {}}
    for fam in a.families.split(","):
        extra = ["protocol.frequencies_hz=[2.0]"] if fam == "cnt_pdms" else []
        cfg = load_scene(fam, extra)
        r = simulate_episodes(cfg, [0], ["ep-0"], make_sensor(cfg, "numpy", "cpu"))[0]
        best = {c: float("inf") for c in CODECS}
        size, chunks = {}, {}
        with tempfile.TemporaryDirectory() as tmp:
            for _ in range(a.repeats):
                for codec in CODECS:
                    path = Path(tmp) / f"{codec}.h5"
                    w = RecordingWriter(path, source="sim", config_json="{}", root_seed=0, shard_index=0,
                                        sensor_attrs={}, mjcf="", compression=codec)
                    with w:
                        t0 = time.perf_counter()
                        for k in range(COPIES):
                            w.add_episode(f"ep-{k:06d}", r.channels, _episode_attrs(r, k))
                        best[codec] = min(best[codec], (time.perf_counter() - t0) / COPIES)
                    size[codec] = path.stat().st_size / COPIES
                    with h5py.File(path, "r") as f:
                        g = f["episodes"] if "episodes" in f else f
                        ep = g[next(iter(g))]
                        chunks[codec] = sum(ep[n].id.get_num_chunks() for n in ep if isinstance(ep[n], h5py.Dataset) and ep[n].chunks)
        res["families"][fam] = {"samples_per_episode": int(r.channels["time"].data.shape[0]), "overrides": extra,
                                "codecs": {c: {"seconds_per_episode": best[c], "bytes_per_episode": size[c],
                                               "chunks_per_episode": chunks[c]} for c in CODECS}}
        print(fam, {c: f"{1e3 * best[c]:.1f} ms, {size[c] / 1e3:.0f} kB" for c in CODECS}, f"{chunks['lzf']} chunks", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"writer-codec-{a.tag}.json"
    path.write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

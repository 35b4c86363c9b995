"""Cost of the per-chunk Fletcher-32 checksums of the recording format: write time, read time and file size
with and without them, for each compression, on episodes of the default preset.

    PYTHONPATH=. python bench/bench_checksum.py [--episodes 16] [--repeats 5] [--frequency 0.5]

Simulates two episodes of the default `cnt_pdms` preset once (620 samples x 225 taxels at 0.5 Hz), then
writes shards of `--episodes` episodes (cycling the two) through `RecordingWriter` with `checksum` off and on,
alternating, `--repeats` times each, and reads every channel back. Writes bench/results/checksum-cpu.json
(the fastest and the median of the repeats, wall and CPU time; the machine is shared, so the fastest and the
CPU time are the steadier figures), and the CPU time of hashing the same data for the content hash.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

COMPRESSIONS = ("lzf", "gzip", "none")


def _source_episodes(frequency: float, tmp: Path) -> list[tuple[dict, dict]]:
    """(channels, attrs) of two simulated episodes of the default preset."""
    from scenes import load_scene
    from sensors.data.recording import Recording
    from sensors.warp_setup import init_warp
    from simulate.generation.executors import generate

    init_warp()
    cfg = load_scene("cnt_pdms", [f"protocol.frequencies_hz=[{frequency}]", "generation.episodes=2",
                                  "generation.episodes_per_shard=2"])
    generate(cfg, tmp / "src", executor="local", workers=1, backend="warp", device="cpu")
    with Recording(tmp / "src" / "shard-00000.h5") as rec:
        return [({n: rec.channel(ep, n) for n in rec.channels(ep)}, rec.episode_attrs(ep)) for ep in rec.episode_ids]


def _write(path: Path, eps, n: int, compression: str, checksum: bool) -> tuple[float, float]:
    """(wall s, CPU s of this process) to write one file."""
    from sensors.data.recording import RecordingWriter

    t0, c0 = time.perf_counter(), time.process_time()
    with RecordingWriter(path, source="sim", config_json="{}", root_seed=0, shard_index=0,
                         sensor_attrs={"family": "cnt_pdms"}, compression=compression, checksum=checksum) as w:
        for k in range(n):
            channels, attrs = eps[k % len(eps)]
            w.add_episode(f"ep-{k:06d}", channels, attrs)
    return time.perf_counter() - t0, time.process_time() - c0


def _content_hash_cpu(eps, n: int) -> float:
    """CPU s to hash n episodes' data the way RecordingWriter does for content_sha256 (in both settings)."""
    from sensors.data.recording import _episode_digest

    c0 = time.process_time()
    for k in range(n):
        channels, attrs = eps[k % len(eps)]
        _episode_digest(f"ep-{k:06d}", attrs, {m: (c.data, c.units, c.dim_names, c.description) for m, c in channels.items()})
    return time.process_time() - c0


def _read(path: Path) -> float:
    t0 = time.perf_counter()
    with h5py.File(path, "r") as f:
        for g in f["episodes"].values():
            for ds in g.values():
                ds[()]
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=8)
    ap.add_argument("--frequency", type=float, default=0.5)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        eps = _source_episodes(a.frequency, tmp)
        n_samples = sum(ch["time"].data.shape[0] for ch, _ in eps)
        raw_bytes = sum(c.data.nbytes for ch, _ in eps for c in ch.values())
        results: dict[str, dict] = {}
        for comp in COMPRESSIONS:
            times: dict[bool, list[float]] = {False: [], True: []}
            cpus: dict[bool, list[float]] = {False: [], True: []}
            reads: dict[bool, list[float]] = {False: [], True: []}
            sizes: dict[bool, int] = {}
            for r in range(a.repeats):
                for checksum in ((False, True) if r % 2 == 0 else (True, False)):  # alternate: no order bias
                    p = tmp / f"{comp}-{checksum}.h5"
                    wall, cpu = _write(p, eps, a.episodes, comp, checksum)
                    times[checksum].append(wall)
                    cpus[checksum].append(cpu)
                    reads[checksum].append(_read(p))
                    sizes[checksum] = p.stat().st_size
                    p.unlink()
            row = {}
            for checksum in (False, True):
                key = "fletcher32" if checksum else "plain"
                row[key] = {"write_s_median": statistics.median(times[checksum]), "write_s_min": min(times[checksum]),
                            "write_s_all": times[checksum], "write_cpu_s_min": min(cpus[checksum]),
                            "read_s_min": min(reads[checksum]),
                            "read_s_median": statistics.median(reads[checksum]), "file_bytes": sizes[checksum]}
            # fastest of the repeats: the least disturbed by the other jobs on the machine
            row["write_time_ratio"] = row["fletcher32"]["write_s_min"] / row["plain"]["write_s_min"]
            row["read_time_ratio"] = row["fletcher32"]["read_s_min"] / row["plain"]["read_s_min"]
            row["write_time_ratio_median"] = row["fletcher32"]["write_s_median"] / row["plain"]["write_s_median"]
            row["size_ratio"] = row["fletcher32"]["file_bytes"] / row["plain"]["file_bytes"]
            row["write_cpu_ratio"] = row["fletcher32"]["write_cpu_s_min"] / row["plain"]["write_cpu_s_min"]
            row["extra_bytes"] = row["fletcher32"]["file_bytes"] - row["plain"]["file_bytes"]
            results[comp] = row
            print(f"{comp:5s} write {row['plain']['write_s_min']:.3f} s -> {row['fletcher32']['write_s_min']:.3f} s "
                  f"(x{row['write_time_ratio']:.3f}), read x{row['read_time_ratio']:.3f}, "
                  f"size +{row['extra_bytes']} B (x{row['size_ratio']:.5f})")
    out = {
        "bench": "checksum",
        "what": "RecordingWriter with and without HDF5 Fletcher-32 per-chunk checksums",
        "preset": "cnt_pdms", "frequency_hz": a.frequency, "episodes_per_file": a.episodes, "repeats": a.repeats,
        "samples_per_episode": n_samples // len(eps), "raw_bytes_per_episode": raw_bytes // len(eps),
        "machine": {"platform": platform.platform(), "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version,
                    "numpy": np.__version__},
        "results": results,
        # hashing the data for the content hash (part of both settings' write time above)
        "content_hash_cpu_s": min(_content_hash_cpu(eps, a.episodes) for _ in range(3)),
    }
    out["content_hash_share_of_lzf_write_cpu"] = out["content_hash_cpu_s"] / results["lzf"]["plain"]["write_cpu_s_min"]
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "checksum-cpu.json"
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

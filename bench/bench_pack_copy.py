"""What the GPU feed's pack costs per byte (issue 16, session 16): copying slice outputs into shared-memory blocks for
the writers (`feed.PackedShard.add_piece`), fresh blocks (as a single-batch run makes them: every page faulted on first
touch) against blocks populated first (`madvise(MADV_POPULATE_WRITE)`) and reused ones, with 4 (`feed.PACK_THREADS`)
and more copy threads. `PYTHONPATH=. python bench/bench_pack_copy.py [--gb 8] [--block-mb 29] [--out FILE]`."""

from __future__ import annotations

import argparse
import json
import mmap
import os
import time
from concurrent.futures import ThreadPoolExecutor
from multiprocessing import shared_memory
from pathlib import Path

import numpy as np

MADV_POPULATE_WRITE = getattr(mmap, "MADV_POPULATE_WRITE", 23)  # Linux >= 5.14


def _copy(blocks, src, threads: int, populate: bool) -> float:
    """Copy src (n_blocks, block bytes) into the blocks, each split in `threads` row ranges as add_piece does."""
    pool = ThreadPoolExecutor(threads)
    t0 = time.perf_counter()
    for shm, row in zip(blocks, src):
        if populate:
            shm._mmap.madvise(MADV_POPULATE_WRITE)
        dst = np.ndarray(row.shape, row.dtype, buffer=shm.buf)
        step = -(-len(row) // threads)
        list(pool.map(lambda r: np.copyto(dst[r : r + step], row[r : r + step]), range(0, len(row), step)))
        dst = None
    dt = time.perf_counter() - t0
    pool.shutdown()
    return dt


def _populate_ahead(blocks, threads: int) -> float:
    """Populate the blocks' pages in `threads` threads (what a driver waiting for its physics could do)."""
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(lambda shm: shm._mmap.madvise(MADV_POPULATE_WRITE), blocks))
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--gb", type=float, default=8.0)
    ap.add_argument("--block-mb", type=float, default=29.0)  # velostat: 8 episodes x 3.6 MB per shard and slice
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    bs = int(a.block_mb * 2**20) // 4 * 4
    n = max(1, int(a.gb * 2**30 // bs))
    src = np.random.default_rng(0).random((n, bs // 4), dtype=np.float32)  # touched, as the staging views are
    gb = src.nbytes / 1e9
    thp = Path("/sys/kernel/mm/transparent_hugepage/shmem_enabled")
    res = {"cpus": os.cpu_count(), "gb": gb, "block_bytes": bs, "blocks": n, "runs": {},
           "shmem_thp": thp.read_text().strip() if thp.exists() else None}

    def fresh():
        return [shared_memory.SharedMemory(create=True, size=bs) for _ in range(n)]

    def drop(blocks):
        for b in blocks:
            b.close()
            b.unlink()

    for threads in (4, 8, 12):
        for mode in ("fresh", "populate", "ahead", "reused"):
            blocks = fresh()
            pre = 0.0
            if mode == "ahead":
                pre = _populate_ahead(blocks, threads)
            if mode == "reused":
                _copy(blocks, src, threads, False)
            dt = _copy(blocks, src, threads, mode == "populate")
            drop(blocks)
            res["runs"][f"{mode}-t{threads}"] = {"seconds": dt, "GB_per_s": gb / dt, "populate_ahead_s": pre}
            print(f"{mode:9s} {threads:2d} threads: {gb / dt:6.2f} GB/s ({dt:.2f} s for {gb:.1f} GB)"
                  + (f"; populated ahead in {pre:.2f} s" if pre else ""), flush=True)
    if a.out:
        a.out.write_text(json.dumps(res, indent=1))
        print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

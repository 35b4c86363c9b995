"""The lateral contact force that MuJoCo Warp's float32 solve leaves on a normal press, by normal force (session 20,
issue 16): what `simulate.contact.load_field.TANGENTIAL_RESIDUAL_N` / `_SHARE` read as 0.

    python bench/gpu_lateral_residual.py RECORDING_OR_DATASET [--out FILE] [--flushed-copy OUT.h5]

Per band of normal force |F_z| (N): samples, the largest lateral force |F_xy| (N) and the largest and median
|F_xy| / |F_z|, over every episode's `contact_force` (C MuJoCo's are exactly 0 on these presses); then the share of
loaded samples under the floor. --flushed-copy writes a copy of a single recording with the floor applied as
`load_batch` applies it (F_xy and that sample's shear field set to 0), e.g. to price the writers on it
(bench/bench_writer_episode.py --cache)."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import h5py
import numpy as np

from simulate.contact.load_field import TANGENTIAL_RESIDUAL_N, TANGENTIAL_RESIDUAL_SHARE, lateral_residual

BANDS_N = [(0.0, 0.01), (0.01, 0.1), (0.1, 1.0), (1.0, 5.0), (5.0, 20.0), (20.0, np.inf)]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("data", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--flushed-copy", type=Path, default=None)
    a = ap.parse_args()
    files = [a.data] if a.data.is_file() else sorted(a.data.rglob("*.h5"))
    t_all, n_all = [], []
    for path in files:
        with h5py.File(path, "r") as f:
            for ep in f["episodes"]:
                cf = f["episodes"][ep]["contact_force"][()].astype(np.float64)
                t_all.append(np.hypot(cf[:, 0], cf[:, 1]))
                n_all.append(np.abs(cf[:, 2]))
    t, n = np.concatenate(t_all), np.concatenate(n_all)
    bands = []
    for lo, hi in BANDS_N:
        s = (n > lo) & (n < hi) if lo == 0 else (n >= lo) & (n < hi)
        if s.any():
            r = t[s] / n[s]
            bands.append({"normal_n": [lo, hi if np.isfinite(hi) else None], "samples": int(s.sum()),
                          "lateral_max_n": float(t[s].max()), "share_max": float(r.max()), "share_median": float(np.median(r))})
    loaded = n > 0
    out = {"data": str(a.data), "files": len(files), "samples": int(t.size), "loaded_samples": int(loaded.sum()),
           "lateral_nonzero_samples": int((t > 0).sum()), "floor_n": TANGENTIAL_RESIDUAL_N,
           "floor_share": TANGENTIAL_RESIDUAL_SHARE, "bands": bands,
           "loaded_under_floor_share": float(lateral_residual(t[loaded], n[loaded]).mean()) if loaded.any() else None,
           "lateral_max_n": float(t.max())}
    for b in bands:
        print(f"|F_z| {b['normal_n']} N: {b['samples']} samples, |F_xy| <= {b['lateral_max_n']:.3g} N, "
              f"share max {b['share_max']:.3g}, median {b['share_median']:.3g}")
    print(f"loaded samples under the floor: {out['loaded_under_floor_share']:.4f}")
    if a.out:
        a.out.write_text(json.dumps(out, indent=1))
        print(f"wrote {a.out}")
    if a.flushed_copy:
        shutil.copyfile(a.data, a.flushed_copy)
        with h5py.File(a.flushed_copy, "r+") as f:
            for ep in f["episodes"]:
                g = f["episodes"][ep]
                cf = g["contact_force"][()]
                res = lateral_residual(np.hypot(cf[:, 0].astype(np.float64), cf[:, 1]), np.abs(cf[:, 2].astype(np.float64)))
                cf[res, :2] = 0
                g["contact_force"][...] = cf
                if "shear" in g:
                    sh = g["shear"][()]
                    sh[res] = 0
                    g["shear"][...] = sh
        print(f"wrote {a.flushed_copy}")


if __name__ == "__main__":
    main()

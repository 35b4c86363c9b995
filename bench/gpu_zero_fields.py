"""How much of each taxel field of a GPU-path dataset is exactly zero, and the size of what is not (session 18, issue
16): the writers leave all-zero chunks unwritten, which on the CPU path drops the shear field of a normal press.

    python bench/gpu_zero_fields.py DATASET_DIR [--out FILE]

Per channel of the recorded episodes: the share of zero values, the share of chunks (as the file lays them out)
that are all zero, the largest |value| and the 99th percentile of |value| among nonzero values, beside the
largest |value| of the pressure for scale."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from sensors.data.recording import Recording, _nonzero_chunks


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--channels", default="shear,pressure,deformation,contact_force")
    a = ap.parse_args()
    names = a.channels.split(",")
    acc = {n: {"values": 0, "zeros": 0, "chunks": 0, "zero_chunks": 0, "absmax": 0.0, "nonzero_abs": []} for n in names}
    for path in sorted(a.dataset.rglob("*.h5")):
        with Recording(path) as r:
            for ep in r.episode_ids:
                for n in names:
                    if n not in r.channels(ep):
                        continue
                    x = r.read(ep, n)
                    s = acc[n]
                    s["values"] += x.size
                    s["zeros"] += int(np.count_nonzero(x.view(f"u{x.dtype.itemsize}") == 0))
                    nz = _nonzero_chunks(np.ascontiguousarray(x), r._f[f"episodes/{ep}/{n}"].chunks)
                    s["chunks"] += nz.size
                    s["zero_chunks"] += int((~nz).sum())
                    s["absmax"] = max(s["absmax"], float(np.abs(x).max()))
                    v = np.abs(x[x != 0])
                    if v.size:
                        s["nonzero_abs"].append(np.quantile(v, [0.5, 0.99]))
    out = {}
    for n, s in acc.items():
        nza = s.pop("nonzero_abs")
        q = np.max(nza, axis=0).tolist() if nza else None
        out[n] = {**s, "zero_share": s["zeros"] / max(1, s["values"]), "zero_chunk_share": s["zero_chunks"] / max(1, s["chunks"]),
                  "nonzero_abs_median_p99_worst_episode": q}
        print(n, json.dumps(out[n]))
    if a.out:
        a.out.write_text(json.dumps({"dataset": str(a.dataset), "channels": out}, indent=1) + "\n")


if __name__ == "__main__":
    main()

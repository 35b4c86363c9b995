"""The dataset manifest's cost after a run of many small shards (issue 16: the fixed cost of a modest run).

`build_manifest` with the writers' entries (what `generate` does after the GPU feed) against the check it made
before session 12's change: opening every shard (`first_missing_shards`). A dataset of N one-episode shards of a
small cnt_pdms scene is generated once (CPU) and reused.

    python bench/bench_manifest.py --shards 1024 [--dataset DIR] [--repeats 3]
writes bench/results/manifest-cpu-s12.json
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv=None):
    from sensors.data import manifest as mf

    ap = argparse.ArgumentParser()
    ap.add_argument("--shards", type=int, default=1024)
    ap.add_argument("--dataset", type=Path, default=Path("/tmp/piezotwin-bench-manifest"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", default="cpu-s12")
    a = ap.parse_args(argv)
    d = a.dataset
    if not (d / "manifest.json").is_file() or mf.read_manifest(d)["n_shards"] != a.shards:
        subprocess.run([sys.executable, "-m", "piezotwin", "generate", "cnt_pdms", "-o", str(d), "--episodes", str(a.shards),
                        "--set", "protocol.frequencies_hz=[2.0]", "--set", "protocol.cycles=1", "--set", "pad.taxels_x=5",
                        "--set", "pad.taxels_y=5", "--set", "generation.episodes_per_shard=1"],
                       check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    m = mf.read_manifest(d)
    described = dict(enumerate(m["shards"]))
    kw = dict(name=m["name"], n_shards=m["n_shards"], episodes_per_shard=m["episodes_per_shard"],
              config_sha256=m["config_sha256"], root_seed=m["root_seed"],
              extra={k: m[k] for k in ("paper", "family", "episodes") if k in m})
    def manifest():  # all but the time it was written
        return {k: v for k, v in mf.read_manifest(d).items() if k != "created_utc"}

    want = manifest()
    now, check = [], []
    for _ in range(a.repeats):
        t = time.perf_counter()
        mf.build_manifest(d, described=described, **kw)
        now.append(time.perf_counter() - t)
        t = time.perf_counter()
        missing = mf.first_missing_shards(d, m["n_shards"], m["config_sha256"])
        check.append(time.perf_counter() - t)
        assert not missing
    same = manifest() == want
    res = {"host": platform.node(), "shards": a.shards, "repeats": a.repeats,
           "build_manifest_with_writer_entries_s": now, "every_shard_opened_s (the check no longer made)": check,
           "per_shard_open_ms": 1e3 * min(check) / a.shards, "manifest_equal_to_generate_s": same}
    out = ROOT / "bench" / "results" / f"manifest-{a.tag}.json"
    out.write_text(json.dumps(res, indent=1))
    print(f"{a.shards} shards: build_manifest {min(now):.3f} s; opening every shard {min(check):.3f} s "
          f"({res['per_shard_open_ms']:.2f} ms each); manifest equal to generate's: {same}; wrote {out}")


if __name__ == "__main__":
    main()

"""What the session-11 writers would make of session 10's H100 CLI runs: an estimate, not a measurement.

    python bench/estimate_h100_writers.py [--writers results/writer-episode-cpu.json] [--tag s11]

For each family's plain-CLI run on the H100 (`results/user-cli-h100-s10-<family>.json`: its writer-seconds, its
wait for the writers, its file bytes) and this machine's writer cost per episode before and after
(`results/writer-episode-cpu.json`: CPU ms per episode of the parts inside `add_episode`, the base revision with the
codec the H100 run used, this checkout with the codec `auto` takes now; bytes per episode likewise):

- writer-seconds of the episodes scale by the ratio of the parts before closing (objects, data, digest, other);
  "close, fsync" and "sha256" scale by the ratio of bytes per episode (fsync and the file's hash go by the bytes);
- the writers' work is spread over the run's W writers; the wait for them at the end shrinks by the writer-seconds
  saved / W, down to 0 (where the wait was not writer-bound, this over-estimates the gain);
- the run's seconds shrink by the wait saved; samples per second and the share of the disk's raw write speed (for
  the estimated bytes) follow; against stepping alone where the run had it.

The H100 host's writer cost per episode was not measured here; the ratio carries this machine's before / after to
it. Writes results/writer-h100-estimate-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
RUNS = {"cnt_pdms": "cnt", "fabric_1": "fabric", "velostat": "velostat", "ntype": "ntype"}
BEFORE_CLOSE = ("objects, attributes", "data", "digest", "other")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--writers", type=Path, default=RESULTS / "writer-episode-cpu.json")
    ap.add_argument("--tag", default="s11")
    ap.add_argument("--writer-processes", type=int, default=12, help="the H100 runs' writers (auto on 16 cores)")
    a = ap.parse_args()
    w = json.loads(a.writers.read_text())
    out = {"estimate": True, "writers_file": a.writers.name, "base": w["base"], "head": w["head"], "families": {}}
    for fam, key in RUNS.items():
        src = RESULTS / f"user-cli-h100-s10-{key}.json"
        run = json.loads(src.read_text())["runs"][fam]
        feed = run["timings"]["feed"]
        old_codec = "lz4" if fam == "cnt_pdms" else "lzf"  # session 10's auto: lz4 for cnt_pdms only
        b, h = w["families"][fam]["base"][old_codec], w["families"][fam]["head"]["lz4"]
        cpu_ratio = sum(h["ms_per_episode"][k] for k in BEFORE_CLOSE) / sum(b["ms_per_episode"][k] for k in BEFORE_CLOSE)
        byte_ratio = h["bytes_per_episode"] / b["bytes_per_episode"]
        old_ws = feed["writers: episodes"] + feed["writers: close, fsync"] + feed["writers: sha256"]
        new_ws = (feed["writers: episodes"] * cpu_ratio
                  + (feed["writers: close, fsync"] + feed["writers: sha256"]) * byte_ratio)
        old_wait = feed["wait for writers"]
        new_wait = max(0.0, old_wait - (old_ws - new_ws) / a.writer_processes)
        secs = run["seconds"] - (old_wait - new_wait)
        nbytes = run["file_bytes"] * byte_ratio
        est = {"from": src.name, "episodes": run["episodes"], "codec_before": old_codec, "codec_now": "lz4",
               "writer_cpu_ratio": cpu_ratio, "bytes_ratio": byte_ratio,
               "writer_seconds": [old_ws, new_ws], "wait_for_writers_s": [old_wait, new_wait],
               "seconds": [run["seconds"], secs], "samples_per_s": [run["samples_per_s"], run["samples"] / secs],
               "of_raw": [run["of_raw"], nbytes / 1e6 / secs / run["raw_MB_per_s_same_bytes"]],
               "target": ">= 50 % of raw or >= 1e6 samples/s; >= 80 % of stepping alone where it bounds"}
        alone = run.get("mjw_alone", {}).get("seconds")  # MuJoCo Warp stepping the same episodes alone, same file
        if alone:
            est["stepping_alone_s"] = alone
            est["of_stepping_alone"] = [alone / run["seconds"], alone / secs]
        out["families"][fam] = est
        print(f"{fam}: writers {old_ws:.0f} -> {new_ws:.0f} writer-s, wait {old_wait:.1f} -> {new_wait:.1f} s, run "
              f"{run['seconds']:.1f} -> {secs:.1f} s, {run['samples_per_s']:.3g} -> {run['samples'] / secs:.3g} samples/s, "
              f"of raw {run['of_raw']:.1%} -> {est['of_raw'][1]:.1%}"
              + (f", of stepping alone {est['of_stepping_alone'][0]:.0%} -> {est['of_stepping_alone'][1]:.0%}"
                 if alone else ""))
    path = RESULTS / f"writer-h100-estimate-{a.tag}.json"
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

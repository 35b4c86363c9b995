"""Replace window networks of a recorded ntype run (`bench/results/experiments/ntype-full*.json`, the paper's task)
by a run of those windows (added where the record has none) on the same data and folds with other settings
(`bench/ntype_full_part.py --models rbf_win --centres-win N`), through `learn.experiments.ntype.merge_runs` (the
findings recomputed on the union); the record's machine note says what ran where.

  python3 bench/ntype_window_rerun.py --record bench/results/experiments/ntype-full-paper.json --part /tmp/nt5k \
      --note "window 5 re-run with 2700 centres ..."
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path


def main() -> None:
    from learn.experiments.ntype import merge_runs

    ap = argparse.ArgumentParser()
    ap.add_argument("--record", type=Path, required=True)
    ap.add_argument("--part", type=Path, required=True, help="the part's output folder (metrics.json, run_info.json)")
    ap.add_argument("--note", required=True)
    a = ap.parse_args()
    rec = json.loads(a.record.read_text())
    part = json.loads((a.part / "metrics.json").read_text())
    info = json.loads((a.part / "run_info.json").read_text())
    kept = {**rec, "models": dict(rec["models"]),
            "protocol": {**rec["protocol"], "windows": []},
            "timing_s": {k: v for k, v in rec.get("timing_s", {}).items() if k != "rbf_win"}}
    new_w = set(part["models"]["rbf_win"])
    old_w = [w for w in rec["models"].get("rbf_win", {}) if w not in new_w]
    kept["models"]["rbf_win"] = {w: rec["models"]["rbf_win"][w] for w in old_w}
    if not old_w:
        del kept["models"]["rbf_win"]
    merged = merge_runs([kept, part])
    merged["protocol"]["centres_win"] = part["protocol"]["centres_win"]  # the re-run windows'
    if old_w:  # windows kept from the record ran with its centres
        by_w = {**{w: rec["protocol"].get("centres_win_by_window", {}).get(w, rec["protocol"]["centres_win"]) for w in old_w},
                **{w: part["protocol"]["centres_win"] for w in new_w}}
        merged["protocol"]["centres_win_by_window"] = {w: by_w[w] for w in sorted(by_w, key=int)}
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    merged["machine"] = {**rec["machine"], "note": rec["machine"]["note"] + "; then " + a.note
                         + f" (git {commit}; {info['cpu_s']:.0f} CPU-s, {info['wall_s'] / 60:.1f} min wall, "
                         f"{info['threads']} thread(s), centres_win {info['centres_win']})"}
    a.record.write_text(json.dumps(merged, indent=1))
    print(f"wrote {a.record}")


if __name__ == "__main__":
    main()

"""Every recorded sim2real split before and after round 11's validation tail (by loaded presses; CHANGELOG, eleventh
round: adopted on its definition, every result re-scored and reported win or lose).

    python bench/bench_s2r_tail_compare.py --before b833838 -o bench/results/s2r-tail-before-after.json

Reads bench/results/experiments/sim2real-*.json at the git revision ``--before`` (the sample-cut tails, rounds 4-10)
and in the working tree (the press tails), and writes per split: the tails' size, the test numbers (pooled and
two-point % FS, fine-tuned / scratch / static curve by budget), the validation-tail RMSEs and the targets.
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path

SPLITS = ("velostat-pike1-to-pike2", "velostat-pike2-to-pike1", "tams-nosil-held-out", "tams-thinsil-held-out",
          "tams-thicksil-held-out")


def digest(m: dict) -> dict:
    r = m["results"]
    return {"validation": m.get("validation"), "tail_full_scale_n": m.get("tail_full_scale_n"),
            "pooled_pct_fs": r["finetuned"]["rmse_pct_full_scale"],
            "two_point_pct_fs": r["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"],
            "curve": [{"n_runs": c["n_runs"], "finetuned_rmse": c["finetuned_rmse"], "scratch_rmse": c["scratch_rmse"],
                       "static_curve_rmse": c["static_curve_rmse"], "finetuned_valid_rmse": c.get("finetuned_valid_rmse"),
                       "scratch_valid_rmse": c.get("scratch_valid_rmse"),
                       "finetune_best_epochs": [s.get("finetune_best_epoch") for s in c.get("seeds", [])],
                       "ft_beats_both": c["finetuned_rmse"] < min(c["scratch_rmse"], c["static_curve_rmse"])}
                      for c in m["learning_curve"]],
            "targets": m.get("targets")}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True, help="git revision holding the earlier results files")
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    out = {"before_revision": a.before, "splits": {}}
    for sp in SPLITS:
        rel = f"bench/results/experiments/sim2real-{sp}.json"
        old = json.loads(subprocess.run(["git", "show", f"{a.before}:{rel}"], check=True, capture_output=True, text=True).stdout)
        new = json.loads(Path(rel).read_text())
        out["splits"][sp] = {"before": digest(old), "after": digest(new)}
    a.out.write_text(json.dumps(out, indent=1))
    for sp, d in out["splits"].items():
        b, n = d["before"], d["after"]
        print(sp, f"pooled {b['pooled_pct_fs']:.1f} -> {n['pooled_pct_fs']:.1f} %",
              " | ".join(f"{cb['n_runs']}: {cb['finetuned_rmse']:.3f}->{cn['finetuned_rmse']:.3f}" for cb, cn in zip(b["curve"], n["curve"])))


if __name__ == "__main__":
    main()

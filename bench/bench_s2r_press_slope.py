"""Does drawing each press's own sensitivity help? Two `sim2real` run folders of one split, the same code and seeds,
press_slope off (the default) and on (`learn.sim2real.S2R_BUDGET["press_slope"]`), compared on the TRAINING side:

    python bench/bench_s2r_press_slope.py RUN_OFF RUN_ON -o bench/results/s2r-press-slope-<split>.json

The adoption rule, fixed before either run was scored: adopt if the fine-tuned RMSE on the training runs' own
validation tails (learn.finetune.split_tail), mean over the learning curve's budgets and seeds, is lower with it in
both Lupasic directions. Beside it: the pre-trained net's RMSE on the real training runs, and, reported only (never
used to choose), the test numbers.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def summary(run: Path) -> dict:
    m = json.loads((run / "metrics.json").read_text())
    lc = m["learning_curve"]
    return {"run": str(run), "press_slope": m.get("press_slope"),
            "pretrain_sim_valid_rmse": m["steps"]["pretrain"]["sim_valid_rmse"],
            "zero_shot_training_runs_rmse": m["results"]["zero_shot"]["training_runs_rmse"],
            "finetuned_valid_rmse_mean": float(np.mean([c["finetuned_valid_rmse"] for c in lc])),
            "curve": [{"n_runs": c["n_runs"], "finetuned_valid_rmse": c["finetuned_valid_rmse"],
                       "scratch_valid_rmse": c["scratch_valid_rmse"], "test_finetuned_rmse": c["finetuned_rmse"],
                       "test_scratch_rmse": c["scratch_rmse"], "test_static_curve_rmse": c["static_curve_rmse"]} for c in lc],
            "test_zero_shot_rmse": m["results"]["zero_shot"]["rmse"],
            "test_two_point_pct_fs": m["results"]["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"]}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("off", type=Path)
    ap.add_argument("on", type=Path)
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    off, on = summary(a.off), summary(a.on)
    out = {"off": off, "on": on, "training_side_helps": on["finetuned_valid_rmse_mean"] < off["finetuned_valid_rmse_mean"],
           "rule": "adopt if the fine-tuned validation RMSE on the training runs' tails (mean over budgets and seeds) "
                   "is lower with press_slope in both Lupasic directions"}
    a.out.write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ("training_side_helps",)} | {s: {k: out[s][k] for k in ("finetuned_valid_rmse_mean", "zero_shot_training_runs_rmse")} for s in ("off", "on")}))


if __name__ == "__main__":
    main()

"""Does giving the simulated presses the sensor's rated range help? Two `sim2real` run folders of one split, the same
code and seeds, without and with `--rated-force-n` (learn.sim2real.S2R_BUDGET["rated_force_n"]), compared on the
TRAINING side:

    python bench/bench_s2r_rated_range.py RUN_WITHOUT RUN_WITH -o bench/results/s2r-rated-range-<split>.json

The adoption rule, fixed before either run was scored: adopt if the fine-tuned RMSE on the training runs' own
validation tails (learn.finetune.split_tail), mean over the learning curve's budgets and seeds, does not get worse
(<=) with the rated range in both Lupasic directions. The training tails lie inside the training range, so they cannot
show the extrapolation the rated range is for; the rule only guards against it costing the training range. Beside it,
reported only (never used to choose): the test numbers, per test run for the largest budget.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from bench_s2r_press_slope import summary


def side(run: Path) -> dict:
    m = json.loads((run / "metrics.json").read_text())
    return {**summary(run), "simulated_peak_force_n": m.get("simulated_peak_force_n"),
            "rated_force_n": (m.get("budget") or {}).get("rated_force_n"),
            "test_finetuned_per_run_rmse_all_runs": m["results"]["finetuned"]["per_run_rmse"],
            "test_static_curve_per_run_rmse_all_runs": m["results"]["static_curve"]["per_run_rmse"],
            "test_finetuned_pct_fs": m["results"]["finetuned"]["rmse_pct_full_scale"]}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("without", type=Path)
    ap.add_argument("rated", type=Path)
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    off = side(a.without)
    if (a.rated / "metrics.json").is_file():
        on = side(a.rated)
    else:  # stopped after its fit: where the rated range lies inside the training presses' range the Randomization
        # (and so the generation, pre-training and fine-tuning, same seeds) is the run without it; checked here
        ra, rb = (json.loads((r / "fit.json").read_text())["randomization"] for r in (a.without, a.rated))
        if ra != rb:
            raise SystemExit(f"{a.rated}: no metrics.json and a Randomization unlike {a.without}'s")
        key = json.loads((a.rated / "state.json").read_text())["key"]
        on = {**off, "run": str(a.rated), "rated_force_n": key["budget"].get("rated_force_n"),
              "simulated_peak_force_n": {"low": rb["press"]["peak_force_n"]["low"], "high": rb["press"]["peak_force_n"]["high"],
                                         "rated_force_n": key["budget"].get("rated_force_n")},
              "identical_randomization": True}
    out = {"without": off, "rated": on,
           "training_side_not_worse": on["finetuned_valid_rmse_mean"] <= off["finetuned_valid_rmse_mean"],
           "rule": "adopt if the fine-tuned validation RMSE on the training runs' tails (mean over budgets and seeds) "
                   "does not get worse with the rated range in both Lupasic directions (the tails cannot show the "
                   "extrapolation; test numbers reported, unused)"}
    a.out.write_text(json.dumps(out, indent=1))
    print(json.dumps({"training_side_not_worse": out["training_side_not_worse"]}
                     | {s: {k: out[s][k] for k in ("finetuned_valid_rmse_mean", "zero_shot_training_runs_rmse", "simulated_peak_force_n")}
                        for s in ("without", "rated")}))


if __name__ == "__main__":
    main()

"""Does drawing each simulated run's ln gain from the hierarchical run-level sd help? Two `sim2real` run folders of
one split, the same code and seeds, without and with `--run-level` (learn.sim2real.S2R_BUDGET["run_level"];
sensors.chain_fit.run_level_sd), compared on the TRAINING side:

    python bench/bench_s2r_run_level.py RUN_WITHOUT RUN_WITH -o bench/results/s2r-run-level-<split>.json

The adoption rule, fixed before either run was scored (CHANGELOG, sixth round): adopt if the fine-tuned RMSE on the
training runs' own validation tails (learn.finetune.split_tail), mean over the learning curve's budgets and seeds,
does not get worse (<=) with the run-level draw in both Lupasic directions. Beside it, reported only (never used to
choose): the simulated run gain sd of each side, and the test numbers.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from bench_s2r_press_slope import summary


def side(run: Path) -> dict:
    m = json.loads((run / "metrics.json").read_text())
    fj = json.loads((run / "fit.json").read_text())
    return {**summary(run), "run_level": bool((m.get("budget") or {}).get("run_level")),
            "episode_gain_log_sd": fj["randomization"]["episode"]["gain_log"]["sd"],
            "test_finetuned_pct_fs": m["results"]["finetuned"]["rmse_pct_full_scale"]}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("without", type=Path)
    ap.add_argument("with_", metavar="with", type=Path)
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    off, on = side(a.without), side(a.with_)
    out = {"without": off, "run_level": on,
           "training_side_not_worse": on["finetuned_valid_rmse_mean"] <= off["finetuned_valid_rmse_mean"],
           "rule": "adopt if the fine-tuned validation RMSE on the training runs' tails (mean over budgets and seeds) "
                   "does not get worse with the run-level draw in both Lupasic directions (test numbers reported, unused)"}
    a.out.write_text(json.dumps(out, indent=1))
    print(json.dumps({"training_side_not_worse": out["training_side_not_worse"]}
                     | {s: {k: out[s][k] for k in ("finetuned_valid_rmse_mean", "zero_shot_training_runs_rmse", "episode_gain_log_sd")}
                        for s in ("without", "run_level")}))


if __name__ == "__main__":
    main()

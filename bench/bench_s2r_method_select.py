"""The warm start chosen on the validation tails (plain or shrink-and-perturb), scored offline by the rule written
before it ran (session 26, issue 15; `results/s2r-method-select-rule.md`).

    python bench/bench_s2r_method_select.py [-o bench/results/s2r-method-select.json]

Per split, the recorded plain run (`results/experiments/sim2real-<split>.json`) and session 25's shrink_perturb run of
the same fit and pre-trained net (`results/s2r-shrink-perturb.json` names its folder; its metrics.json). At every
budget and training seed the method with the lower validation loss on the budget's tails
(`finetune_valid_mse_z_best`) is kept with its test RMSE; fine-tuned = the mean over the seeds, as the loop reports.
Both runs must share the budgets, seeds and scratch numbers (the same fit, pre-training and tails), else the split
is flagged.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results"


def _recorded(split: str) -> Path:
    return RESULTS / "experiments" / (f"sim2real-{split}.json" if split.startswith("tams-") else f"sim2real-velostat-{split}.json")


def select(plain: dict, sp: dict) -> dict:
    rows = []
    for a, b in zip(plain["learning_curve"], sp["learning_curve"]):
        assert a["n_runs"] == b["n_runs"]
        pick, test = [], []
        for sa, sb, ta, tb in zip(a["seeds"], b["seeds"], a["finetuned_rmse_seeds"], b["finetuned_rmse_seeds"]):
            assert sa["seed"] == sb["seed"]
            use_sp = sb["finetune_valid_mse_z_best"] < sa["finetune_valid_mse_z_best"]
            pick.append("shrink_perturb" if use_sp else "plain")
            test.append(tb if use_sp else ta)
        same_scratch = bool(np.allclose(a["scratch_rmse_seeds"], b["scratch_rmse_seeds"], rtol=1e-9, atol=1e-12))
        sel = float(np.mean(test))
        rows.append({"n_runs": a["n_runs"], "plain": a["finetuned_rmse"], "shrink_perturb": b["finetuned_rmse"],
                     "selected": sel, "picked": pick, "rel_change": sel / a["finetuned_rmse"] - 1,
                     "scratch": a["scratch_rmse"], "static_curve": a["static_curve_rmse"], "same_scratch": same_scratch})
    return {"curve": rows}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "s2r-method-select.json")
    a = ap.parse_args()
    runs = json.loads((RESULTS / "s2r-shrink-perturb.json").read_text())["splits"]
    out = {"rule": "results/s2r-method-select-rule.md", "splits": {}}
    for split, v in runs.items():
        plain = json.loads(_recorded(split).read_text())
        sp = json.loads((Path(v["run"]) / "metrics.json").read_text())
        r = select(plain, sp)
        r["full_scale_n"] = plain["full_scale_n"]
        r["sp_run"] = v["run"]
        out["splits"][split] = r
        print(split, " | ".join(f"{c['n_runs']}: {c['plain']:.4g} -> {c['selected']:.4g} ({100 * c['rel_change']:+.1f} %, "
                                f"{','.join(p[0] for p in c['picked'])}{'' if c['same_scratch'] else ', SCRATCH DIFFERS'})"
                                for c in r["curve"]))
    fwd = out["splits"]["pike1-to-pike2"]["curve"][-1]["rel_change"]
    rel = [c["rel_change"] for s in out["splits"].values() for c in s["curve"]]
    out["checks"] = {"pike1_to_pike2_all_runs_falls_5pct": fwd <= -0.05, "no_budget_rises_10pct": max(rel) <= 0.10,
                     "mean_change_le_0": float(np.mean(rel)) <= 0.0}
    out["mean_rel_change"] = float(np.mean(rel))
    out["consistent"] = all(c["same_scratch"] for s in out["splits"].values() for c in s["curve"])
    out["adopted"] = all(out["checks"].values()) and out["consistent"]
    a.out.write_text(json.dumps(out, indent=1) + "\n")
    print(f"checks {out['checks']}, mean change {100 * out['mean_rel_change']:+.1f} %, consistent {out['consistent']}: "
          f"adopted {out['adopted']}; wrote {a.out}")


if __name__ == "__main__":
    main()

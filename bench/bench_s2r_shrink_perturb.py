"""Shrink-and-perturb fine-tuning scored by the rule written before it ran (session 25, issue 15).

    python bench/bench_s2r_shrink_perturb.py --run pike1-to-pike2=DIR [--run pike2-to-pike1=DIR]
                                             [-o bench/results/s2r-shrink-perturb.json]

Each DIR is a `piezotwin sim2real velostat ... --finetune-method shrink_perturb` run of that split (pike1 -> pike2: a
copy of the recorded run's directory, so its fit and pre-trained checkpoint are reused and only the fine-tuning and
its baselines ran again; pike2 -> pike1: a full loop at pipeline seed 0, as recorded). The reference is the recorded
plain fine-tuning, `results/experiments/sim2real-velostat-<split>.json`. The rule
(`results/s2r-shrink-perturb-rule.md`): adopt only if, per split, (1) the all-runs fine-tuned test RMSE falls by >= 5 %,
(2) the mean relative change over the budgets is <= -5 %, (3) no budget rises by more than 10 %; pike1 -> pike2 first,
then the same on pike2 -> pike1. TAMS covers left out (`--run tams-<cover>-held-out=DIR`, each a full loop with the
recorded run's command plus the method) are reported beside them, outside the rule.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def _curve(m: dict) -> dict[str, dict[str, float]]:
    return {str(e["n_runs"]): {k: e[k] for k in ("finetuned_rmse", "scratch_rmse", "static_curve_rmse")}
            for e in m["learning_curve"]}


def _reference(split: str) -> str:
    return f"sim2real-{split}.json" if split.startswith("tams-") else f"sim2real-velostat-{split}.json"


def score(split: str, run_dir: Path) -> dict:
    ref = json.loads((RESULTS / "experiments" / _reference(split)).read_text())
    got = json.loads((run_dir / "metrics.json").read_text())
    rc, gc = _curve(ref), _curve(got)
    budgets = [b for b in rc if b in gc]
    rel = {b: (gc[b]["finetuned_rmse"] - rc[b]["finetuned_rmse"]) / rc[b]["finetuned_rmse"] for b in budgets}
    all_runs = max(budgets, key=int)
    checks = {"all_runs_falls_5pct": rel[all_runs] <= -0.05,
              "mean_change_le_minus_5pct": sum(rel.values()) / len(rel) <= -0.05,
              "no_budget_rises_10pct": max(rel.values()) <= 0.10}
    r, g = ref["results"], got["results"]
    return {
        "split": split, "run": str(run_dir), "reference": f"experiments/{_reference(split)}",
        "full_scale_n": got["full_scale_n"],
        "finetuned_rmse": {"plain": r["finetuned"]["rmse"], "shrink_perturb": g["finetuned"]["rmse"]},
        "finetuned_pct_full_scale": {"plain": r["finetuned"]["rmse_pct_full_scale"],
                                     "shrink_perturb": g["finetuned"]["rmse_pct_full_scale"]},
        "finetuned_rmse_seeds": {"plain": r["finetuned"].get("rmse_seeds"), "shrink_perturb": g["finetuned"].get("rmse_seeds")},
        "scratch_rmse": {"plain run": r["scratch"]["rmse"], "this run": g["scratch"]["rmse"]},
        "static_curve_rmse": {"plain run": r["static_curve"]["rmse"], "this run": g["static_curve"]["rmse"]},
        "curve": {b: {"plain": rc[b], "shrink_perturb": gc[b], "finetuned_rel_change": rel[b]} for b in budgets},
        "best_epochs": [[s.get("finetune_best_epoch") for s in e["seeds"]] for e in got["learning_curve"]],
        "checks": checks, "passes": all(checks.values()), "targets": got["targets"],
        "seconds": got.get("seconds_total_this_call"),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="append", required=True,
                    help="SPLIT=DIR (pike1-to-pike2, pike2-to-pike1, or tams-<cover>-held-out: reported, outside the rule)")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "s2r-shrink-perturb.json")
    a = ap.parse_args()
    splits = {}
    for item in a.run:
        split, d = item.split("=", 1)
        splits[split] = score(split, Path(d))
    order = [s for s in ("pike1-to-pike2", "pike2-to-pike1") if s in splits]
    adopted = len(order) == 2 and all(splits[s]["passes"] for s in order)
    out = {"rule": "results/s2r-shrink-perturb-rule.md", "candidate": "finetune_method=shrink_perturb (SP_SHRINK 0.5, "
           "SP_NOISE 0.1, estimates)", "splits": splits, "adopted": adopted}
    a.out.write_text(json.dumps(out, indent=1) + "\n")
    for s in splits:
        v = splits[s]
        print(f"{s}: fine-tuned {v['finetuned_rmse']['plain']:.2f} -> {v['finetuned_rmse']['shrink_perturb']:.2f} N; "
              + ", ".join(f"{b} runs {c['finetuned_rel_change']:+.0%}" for b, c in v["curve"].items())
              + f"; checks {v['checks']}")
    print(f"adopted: {adopted}; wrote {a.out}")


if __name__ == "__main__":
    main()

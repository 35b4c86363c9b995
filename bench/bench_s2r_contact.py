"""The contact-area term scored by the round-8 rule (ninth round of issue 15; rule: CHANGELOG, written before scoring).

    python bench/bench_s2r_contact.py --split pike1-to-pike2 --reference-run REF_RUN --candidate-run RUN \
        --candidate-pipeline CAND.json -o bench/results/s2r-contact-pike1-to-pike2.json

REF_RUN and RUN: finished `sim2real` folders of the split at pipeline seed 0, the defaults and `--fit-contact`.
CAND.json: bench/bench_s2r_pipeline_noise.py's output on RUN for pipeline seeds 1 and 2 (method plain). The
reference's tails at p = 0, 1, 2 are the recorded ones (bench/results/s2r-pipeline-noise-<split>.json, plain).
Recorded: per p the fine-tuned RMSE on the training runs' validation tails (mean over budgets and seeds), the paired
statistic (learn.sim2real.paired_improvement), the pre-trained nets' error on those tails split into level and shape
(learn.sim2real.error_split), the training fits (F_a with its bootstrap range, exponent, within-press error, the
run-mean level trend against ln force and the steady law against the real run means: bench_s2r_force_law), and
beside them, never used to choose, the test numbers.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import numpy as np
from bench_s2r_force_law import real_law, training_levels

RESULTS = Path(__file__).resolve().parent / "results"


def _tail_mean(lc: list[dict]) -> float:
    return float(np.mean([c["finetuned_valid_rmse"] for c in lc]))


def _pre_split(lc: list[dict]) -> list:
    return [c.get("pretrained_valid_error_split_n") for c in lc]


def _test(m: dict) -> dict:
    r = m["results"]
    return {"pooled_pct_fs": r["finetuned"]["rmse_pct_full_scale"], "zero_shot_rmse_n": r["zero_shot"]["rmse"],
            "two_point_pct_fs": r["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"],
            "finetuned_by_budget_n": [c["finetuned_rmse"] for c in m["learning_curve"]],
            "curve": [{k: c[k] for k in ("n_runs", "finetuned_rmse", "scratch_rmse", "static_curve_rmse")} for c in m["learning_curve"]]}


def main(argv=None):
    from learn.sim2real import paired_improvement
    from sensors import chain_fit as C

    ap = argparse.ArgumentParser()
    ap.add_argument("--split", required=True, choices=["pike1-to-pike2", "pike2-to-pike1"])
    ap.add_argument("--reference-run", required=True, type=Path)
    ap.add_argument("--candidate-run", required=True, type=Path)
    ap.add_argument("--candidate-pipeline", required=True, type=Path)
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    ref = json.loads((RESULTS / f"s2r-pipeline-noise-{a.split}.json").read_text())
    cm = json.loads((a.candidate_run / "metrics.json").read_text())
    cp = json.loads(a.candidate_pipeline.read_text())
    test_glob = json.loads((a.candidate_run / "state.json").read_text())["key"]["test"]
    seeds = [0, 1, 2]
    ref_t = [ref["runs"][f"p{p}/plain"]["finetuned_valid_rmse_mean"] for p in seeds]
    cand_t = [_tail_mean(cm["learning_curve"])] + [cp["runs"][f"p{p}/plain"]["finetuned_valid_rmse_mean"] for p in seeds[1:]]
    rule = paired_improvement(ref_t, cand_t)
    cand_pre = [{"pretrained_valid_rmse_mean": float(np.mean([c["pretrained_valid_rmse"] for c in cm["learning_curve"]])),
                 "error_split_by_budget": _pre_split(cm["learning_curve"])}]
    cand_pre += [{"pretrained_valid_rmse_mean": cp["runs"][f"p{p}/plain"]["pretrained_valid_rmse_mean"],
                  "error_split_by_budget": [c["pretrained_valid_error_split_n"] for c in cp["runs"][f"p{p}/plain"]["curve"]]}
                 for p in seeds[1:]]
    ref_pre = [{"pretrained_valid_rmse_mean": ref["runs"][f"p{p}/plain"]["pretrained_valid_rmse_mean"],
                "error_split_by_budget": [c["pretrained_valid_error_split_n"] for c in ref["runs"][f"p{p}/plain"]["curve"]]}
               for p in seeds]
    sides = {}
    for name, run in (("reference", a.reference_run), ("contact", a.candidate_run)):
        lv = training_levels(run, cm["recording"], test_glob, C)
        law = real_law(lv)
        fj = json.loads((run / "fit.json").read_text())
        lv["params"]["contact_force_n"] = fj["params"].get("contact_force_n", 0.0)
        lv["contact_force_n_p5_p50_p95"] = fj["ranges_p5_p50_p95"].get("contact_force_n")
        lv["held_out_beside"] = lv.pop("held_out")
        sides[name] = {"training_fit": lv, "real_training_run_mean_dlnr_dlnf": law}
    cand_test = [_test(cm)] + [{"pooled_pct_fs": cp["runs"][f"p{p}/plain"]["test_pooled_pct_fs"],
                                "two_point_pct_fs": cp["runs"][f"p{p}/plain"]["test_two_point_pct_fs"],
                                "zero_shot_rmse_n": cp["runs"][f"p{p}/plain"]["test_zero_shot_rmse"],
                                "finetuned_by_budget_n": [c["finetuned_rmse"] for c in cp["runs"][f"p{p}/plain"]["curve"]]}
                               for p in seeds[1:]]
    ref_test = [{"pooled_pct_fs": ref["runs"][f"p{p}/plain"]["test_pooled_pct_fs"],
                 "two_point_pct_fs": ref["runs"][f"p{p}/plain"]["test_two_point_pct_fs"],
                 "zero_shot_rmse_n": ref["runs"][f"p{p}/plain"]["test_zero_shot_rmse"],
                 "finetuned_by_budget_n": [c["finetuned_rmse"] for c in ref["runs"][f"p{p}/plain"]["curve"]]} for p in seeds]
    out = {"command": "python bench/bench_s2r_contact.py " + shlex.join(sys.argv[1:] if argv is None else argv),
           "split": a.split, "candidate_command": cm.get("command"), "candidate_pipeline_command": cp.get("command"),
           "rule": ("adopt fit_contact if in BOTH Lupasic directions the mean paired difference (candidate - reference) of "
                    "the fine-tuned validation-tail RMSE over pipeline seeds 0, 1, 2 is below minus its standard error, and "
                    "tests/test_fit.py recovers the known chain (CHANGELOG, ninth round, written before scoring)"),
           "pipeline_seeds": seeds, "valid_tail_reference_n": ref_t, "valid_tail_contact_n": cand_t, "paired": rule,
           "pretrained_on_tails": {"reference": ref_pre, "contact": cand_pre},
           "pretrain_contact": cp.get("pretrain"), "training_fits": sides,
           "test_beside_unused": {"reference": ref_test, "contact": cand_test}}
    a.out.write_text(json.dumps(out, indent=1, default=float))
    print(json.dumps({"valid_tail_reference_n": ref_t, "valid_tail_contact_n": cand_t, "paired": rule}, indent=1))


if __name__ == "__main__":
    main()

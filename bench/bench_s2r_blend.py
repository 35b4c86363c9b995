"""The static-curve residual (learn.sim2real.StaticBlend), eleventh round of issue 15 (rule: CHANGELOG, written before
scoring).

    python bench/bench_s2r_blend.py REAL.h5 --test-episodes GLOB --base RUN --work DIR --pipeline-seeds 0 1 2 \
        -o bench/results/s2r-blend-<split>.json

RUN is a finished `sim2real` folder of the split made with round 11's code (fit.json, checkpoints/pretrained,
metrics.json whose learning curve holds each fit's ``static_blend`` record): p = 0 is read from it. Pipeline seed
p > 0 keeps the fit, the learning curve's run order and the 3 fine-tuning seeds and redraws the generation and the
pre-training in DIR/p<p> (as bench_s2r_pipeline_noise.py); step 4 runs without scratch (the blend is the fine-tuned
net's). Per fit the record holds the blend weight fitted on the first half of the validation tails
(learn.finetune.split_tail(tails, 0.5): the later loaded presses) and the RMSE (N) of the net alone and of the blend
on the second halves, which the weight never saw. The rule's statistic: per p the mean over budgets and fine-tuning
seeds, paired over p (learn.sim2real.paired_improvement, blend - net). Test numbers beside, never used to choose.
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np


def summary(lc: list[dict]) -> dict:
    recs = [(c["n_runs"], s["static_blend"]) for c in lc for s in c["seeds"]]
    ok = [r for _, r in recs if r["second_half_rmse_net_n"] is not None and r["second_half_rmse_blend_n"] is not None]
    return {"net_second_half_mean": float(np.mean([r["second_half_rmse_net_n"] for r in ok])),
            "blend_second_half_mean": float(np.mean([r["second_half_rmse_blend_n"] for r in ok])),
            "static_second_half_mean": float(np.mean([r["second_half_rmse_static_n"] for r in ok])),
            "finetuned_valid_tail_mean": float(np.mean([c["finetuned_valid_rmse"] for c in lc])),
            "n_fits": len(ok),
            "by_budget": [{"n_runs": c["n_runs"],
                           "w_first_half": [s["static_blend"]["w_first_half"] for s in c["seeds"]],
                           "w_tail": [s["static_blend"]["w_tail"] for s in c["seeds"]],
                           "second_half_net_n": [s["static_blend"]["second_half_rmse_net_n"] for s in c["seeds"]],
                           "second_half_blend_n": [s["static_blend"]["second_half_rmse_blend_n"] for s in c["seeds"]],
                           "second_half_static_n": c["seeds"][0]["static_blend"]["second_half_rmse_static_n"],
                           "test_finetuned_rmse": c["finetuned_rmse"], "test_static_curve_rmse": c["static_curve_rmse"],
                           "test_scratch_rmse": c.get("scratch_rmse"),
                           "test_blend_rmse": float(np.mean([s["static_blend"]["test_rmse_blend_n"] for s in c["seeds"]])),
                           "valid_tail_finetuned_n": c["finetuned_valid_rmse"]} for c in lc]}


def main(argv=None):
    import torch
    from bench_s2r_pipeline_noise import pipeline_seed_args, pretrained_checkpoint

    from learn.checkpoint import load_checkpoint
    from learn.sim2real import S2R_BUDGET, _evaluate_loop, paired_improvement
    from scenes.randomize import Randomization
    from sensors import chain_fit as C

    torch.set_num_threads(1)
    ap = pipeline_seed_args()
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    bm = json.loads((a.base / "metrics.json").read_text())
    out = json.loads(a.out.read_text()) if a.out.is_file() else {"runs": {}, "pretrain": {}}
    cmd = "python bench/bench_s2r_blend.py " + shlex.join(sys.argv[1:] if argv is None else argv)
    out.update(commands=[*out.get("commands", []), cmd], real=a.real, test_episodes=a.test_episodes, base=str(a.base),
               base_command=bm.get("command"))
    params, fj = C.load_params(a.base / "fit.json")
    rand = Randomization.model_validate(fj["randomization"])

    def save():
        have = sorted(int(k[1:]) for k in out["runs"])
        if len(have) >= 2:
            ref = [out["runs"][f"p{p}"]["net_second_half_mean"] for p in have]
            cand = [out["runs"][f"p{p}"]["blend_second_half_mean"] for p in have]
            out["rule"] = {**paired_improvement(ref, cand), "pipeline_seeds": have}
        a.out.write_text(json.dumps(out, indent=1, default=float))

    for p in a.pipeline_seeds:
        key = f"p{p}"
        if key in out["runs"]:
            continue
        B = {**S2R_BUDGET, **bm["budget"], "pipeline_seed": p, "static_blend": False}
        t0 = time.perf_counter()
        ck = pretrained_checkpoint(p, a.base, a.work, bm, params, rand, B, out["pretrain"])
        if p == 0:  # the recorded run's learning curve and test results (its fine-tuning is the default's)
            lc = bm["learning_curve"]
            test = {"pooled_pct_fs": bm["results"]["finetuned"]["rmse_pct_full_scale"],
                    "two_point_pct_fs": bm["results"]["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"]}
        else:
            m = _evaluate_loop(load_checkpoint(ck), params, a.real, a.test_episodes, B, 0, "sensor", "force",
                               float(B["fit_rate_hz"]), lambda k, n: None, print, sim=(), scratch=False,
                               fit_json=fj)
            lc = m["learning_curve"]
            test = {"pooled_pct_fs": m["results"]["finetuned"]["rmse_pct_full_scale"],
                    "two_point_pct_fs": m["results"]["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"]}
        out["runs"][key] = {**summary(lc), "test": test, "seconds": time.perf_counter() - t0}
        r = out["runs"][key]
        print(f"{key}: second halves net {r['net_second_half_mean']:.4f} N, blend {r['blend_second_half_mean']:.4f} N "
              f"(static {r['static_second_half_mean']:.4f}), {r['seconds']:.0f} s", flush=True)
        save()
    save()
    print(json.dumps(out.get("rule"), indent=1, default=float))


if __name__ == "__main__":
    main()

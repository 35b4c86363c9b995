"""The pipeline's spread and the fine-tuning methods, eighth round of issue 15 (rule: CHANGELOG, written before scoring).

    python bench/bench_s2r_pipeline_noise.py REAL.h5 --test-episodes GLOB --base RUN --work DIR \
        --pipeline-seeds 0 1 2 --methods plain l2sp lpft -o bench/results/s2r-pipeline-noise-<split>.json

RUN is a finished `sim2real` folder of the split (seed 0: fit.json, sim.h5, checkpoints/pretrained, metrics.json).
Pipeline seed p > 0 keeps its fit (deterministic), the learning curve's run order and the 3 fine-tuning seeds, and
redraws the generation and the pre-training (`budget.pipeline_seed`: steps 2-3 seeded root + 100 p) in DIR/p<p>.
Per (p, method) step 4 runs without scratch (scratch and the static curve do not depend on p or the method): the
fine-tuned RMSE on the training runs' validation tails (mean over budgets and seeds: the adoption metric), per seed,
the pre-trained net's tails and where its error sits (level / shape, learn.sim2real.error_split), and beside them
the test numbers (never used to choose). The output is resumable: (p, method) already in -o are kept.
Plain at p = 0 reruns the recorded runs' fine-tuning (a determinism check against RUN's metrics.json).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np


def one(base_ck: Path, params, real: str, glob: str, B: dict, fj: dict | None = None) -> dict:
    from learn.checkpoint import load_checkpoint
    from learn.sim2real import _evaluate_loop

    base = load_checkpoint(base_ck)
    t0 = time.perf_counter()
    m = _evaluate_loop(base, params, real, glob, B, 0, "sensor", "force", float(B["fit_rate_hz"]), lambda k, n: None,
                       print, sim=(), scratch=False, fit_json=fj)
    lc = m["learning_curve"]
    return {"finetuned_valid_rmse_mean": float(np.mean([c["finetuned_valid_rmse"] for c in lc])),
            "finetuned_valid_rmse_by_seed": [float(np.mean([c["seeds"][i]["finetune_valid_rmse_n"] for c in lc]))
                                             for i in range(len(lc[0]["seeds"]))],
            "pretrained_valid_rmse_mean": float(np.mean([c["pretrained_valid_rmse"] for c in lc])),
            "curve": [{k: c[k] for k in ("n_runs", "finetuned_valid_rmse", "pretrained_valid_rmse", "pretrained_valid_error_split_n",
                                         "finetuned_rmse", "finetuned_rmse_seeds", "static_curve_rmse")}
                      | {"seeds": [{k: s.get(k) for k in ("seed", "finetune_epochs", "finetune_best_epoch", "finetune_valid_mse_z_before",
                                                          "finetune_valid_mse_z_best", "finetune_valid_rmse_n",
                                                          "finetune_valid_error_split_n", "linear_probe")} for s in c["seeds"]]}
                      for c in lc],
            "test_pooled_pct_fs": m["results"]["finetuned"]["rmse_pct_full_scale"],
            "test_zero_shot_rmse": m["results"]["zero_shot"]["rmse"],
            "test_two_point_pct_fs": m["results"]["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"],
            "seconds": time.perf_counter() - t0}


def stats(out: dict, seeds: list[int], methods: list[str]) -> dict:
    from learn.sim2real import paired_improvement

    runs = out["runs"]
    st: dict = {}
    for meth in methods:
        have = [p for p in seeds if f"p{p}/{meth}" in runs]
        v = [runs[f"p{p}/{meth}"]["finetuned_valid_rmse_mean"] for p in have]
        if len(v) >= 2:
            st[meth] = {"pipeline_seeds": have, "valid_tail_mean": float(np.mean(v)), "valid_tail_sd": float(np.std(v, ddof=1)),
                        "valid_tail_se": float(np.std(v, ddof=1) / np.sqrt(len(v))), "valid_tail": v,
                        # the 3 fine-tuning seeds inside one pipeline seed: sd of their tails, se of their mean
                        "train_seed_sd_mean": float(np.mean([np.std(runs[f"p{p}/{meth}"]["finetuned_valid_rmse_by_seed"], ddof=1) for p in have])),
                        "test_by_budget_mean": [float(np.mean([runs[f"p{p}/{meth}"]["curve"][i]["finetuned_rmse"] for p in have]))
                                                for i in range(len(runs[f"p{have[0]}/{meth}"]["curve"]))],
                        "test_by_budget_sd": [float(np.std([runs[f"p{p}/{meth}"]["curve"][i]["finetuned_rmse"] for p in have], ddof=1))
                                              for i in range(len(runs[f"p{have[0]}/{meth}"]["curve"]))],
                        "test_pooled_pct_fs": [runs[f"p{p}/{meth}"]["test_pooled_pct_fs"] for p in have],
                        "test_two_point_pct_fs": [runs[f"p{p}/{meth}"]["test_two_point_pct_fs"] for p in have]}
        if meth != "plain":
            both = [p for p in seeds if f"p{p}/{meth}" in runs and f"p{p}/plain" in runs]
            if len(both) >= 2:
                st.setdefault(meth, {})["vs_plain"] = paired_improvement(
                    [runs[f"p{p}/plain"]["finetuned_valid_rmse_mean"] for p in both],
                    [runs[f"p{p}/{meth}"]["finetuned_valid_rmse_mean"] for p in both]) | {"pipeline_seeds": both}
    return st


def pipeline_seed_args() -> argparse.ArgumentParser:
    """The arguments of the benches that rerun the loop over pipeline seeds (this one, bench_s2r_blend.py,
    bench_s2r_patience.py): the real capture, its test runs, the recorded run (seed 0), a work folder for the
    others and the seeds."""
    ap = argparse.ArgumentParser()
    ap.add_argument("real")
    ap.add_argument("--test-episodes", required=True)
    ap.add_argument("--base", required=True, type=Path)
    ap.add_argument("--work", required=True, type=Path)
    ap.add_argument("--pipeline-seeds", type=int, nargs="+", default=[0, 1, 2])
    return ap


def pretrained_checkpoint(p: int, base: Path, work: Path, bm: dict, params, rand, B: dict, pretrain: dict) -> Path:
    """The pre-trained checkpoint of pipeline seed p: the recorded run's for p = 0 (its pre-training recorded from
    its metrics `bm`), else made once under work/p<p> (randomized generation + pre-training with budget B, whose
    pipeline_seed is p), its pre-training recorded in `pretrain`."""
    from learn.sim2real import generate_step, pretrain_step

    if p == 0:
        pretrain["p0"] = {k: bm["steps"]["pretrain"].get(k) for k in ("sim_valid_rmse", "epochs", "best_epoch", "wall_s")}
        return base / "checkpoints" / "pretrained"
    d = work / f"p{p}"
    d.mkdir(parents=True, exist_ok=True)
    ck = d / "checkpoints" / "pretrained"
    if not (ck / "config.json").is_file():
        t0 = time.perf_counter()
        generate_step(params, rand, d / "sim.h5", B, 0)
        info = pretrain_step(d / "sim.h5", ck, "tcn", B, 0)
        pretrain[f"p{p}"] = {**info, "wall_s": time.perf_counter() - t0}
        print(f"p{p} pre-trained: {info}", flush=True)
    return ck


def main(argv=None):
    import torch

    from learn.sim2real import S2R_BUDGET
    from scenes.randomize import Randomization
    from sensors import chain_fit as C

    torch.set_num_threads(1)
    ap = pipeline_seed_args()
    ap.add_argument("--methods", nargs="+", default=["plain", "l2sp", "lpft"])
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    bm = json.loads((a.base / "metrics.json").read_text())
    out = json.loads(a.out.read_text()) if a.out.is_file() else {"runs": {}, "pretrain": {}}
    cmd = "python bench/bench_s2r_pipeline_noise.py " + shlex.join(sys.argv[1:] if argv is None else argv)
    out.update(command=cmd, commands=[*out.get("commands", []), cmd], real=a.real, test_episodes=a.test_episodes, base=str(a.base), base_command=bm.get("command"))
    params, fj = C.load_params(a.base / "fit.json")
    rand = Randomization.model_validate(fj["randomization"])

    def save():
        out["stats"] = stats(out, sorted({int(k.split("/")[0][1:]) for k in out["runs"]}), ["plain", "l2sp", "lpft"])
        a.out.write_text(json.dumps(out, indent=1, default=float))

    for p in a.pipeline_seeds:
        B = {**S2R_BUDGET, **bm["budget"], "pipeline_seed": p}
        ck = pretrained_checkpoint(p, a.base, a.work, bm, params, rand, B, out["pretrain"])
        for meth in a.methods:
            key = f"p{p}/{meth}"
            if key in out["runs"]:
                continue
            r = one(ck, params, a.real, a.test_episodes, {**B, "finetune_method": meth}, fj)
            if p == 0 and meth == "plain":  # the recorded runs' fine-tuning, rerun: equal if the pipeline is deterministic
                rec = [c["finetuned_valid_rmse"] for c in bm["learning_curve"]]
                r["determinism_check"] = {"recorded_valid_by_budget": rec, "rerun_valid_by_budget": [c["finetuned_valid_rmse"] for c in r["curve"]],
                                          "max_abs_diff": float(np.max(np.abs(np.subtract(rec, [c["finetuned_valid_rmse"] for c in r["curve"]]))))}
            out["runs"][key] = r
            print(f"{key}: valid tail {r['finetuned_valid_rmse_mean']:.4f} N (seeds {np.round(r['finetuned_valid_rmse_by_seed'], 4)}), "
                  f"{r['seconds']:.0f} s", flush=True)
            save()
    save()
    print(json.dumps(out["stats"], indent=1, default=float))


if __name__ == "__main__":
    main()

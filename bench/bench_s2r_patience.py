"""Early stopping of the fine-tuning, tenth round of issue 15 (rule and candidate: CHANGELOG, written before scoring).

    python bench/bench_s2r_patience.py REAL.h5 --test-episodes GLOB --base RUN --work DIR \
        --pipeline-seeds 0 1 2 -o bench/results/s2r-patience-<split>.json

RUN is the recorded `sim2real` folder of the split (p = 0: checkpoints/pretrained, metrics.json); DIR/p<p> holds the
pre-trained nets of pipeline seeds p > 0 (bench_s2r_pipeline_noise.py made them). For every (pipeline seed, budget,
fine-tuning seed) of step 4 the fine-tuning runs its whole epoch cap (no early termination) and a probe records, per
epoch (-1: the pre-trained net), the validation loss that stops training (z-MSE on the validation tails, as
learn.train.train_model computes it), the RMSE (N) on the tails, and, for the held-out check, the z-MSE on the first
half of each tail and the RMSE (N) on its second half (learn.finetune.split_tail(tails, 0.5): cut between presses).
Training does not depend on the patience (the same seed gives the same epochs), so one run per fit gives both
stopping rules exactly: stopping with patience P is replayed on the recorded curve (best epoch by the strict
improvement of train_model, stop after P epochs without one). The default's replay must give the recorded
validation tails (the determinism check). Never reads the test runs.
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np


def one_fit(base, heads, tails, kw: dict, seed: int, cap: int) -> dict:
    import torch

    from learn import finetune as FT
    from learn.train import evaluate

    t1, t2 = FT.split_tail(tails, 0.5)
    rec: dict[str, list[float]] = {"valid_z": [], "tail_n": [], "t1_z": [], "t2_n": []}

    def probe(epoch: int, c) -> None:
        ex = c._examples([c.x_norm.apply(s.x) for s in tails], [c.y_norm.apply(s.y) for s in tails], False)
        e1 = c._examples([c.x_norm.apply(s.x) for s in t1], [c.y_norm.apply(s.y) for s in t1], False)
        with torch.no_grad():
            rec["valid_z"].append(evaluate(c.net, *ex))
            rec["t1_z"].append(evaluate(c.net, *e1))
        rec["tail_n"].append(FT.rmse_on(c, tails))
        rec["t2_n"].append(FT.rmse_on(c, t2))

    _, info = FT.finetune(base, heads, tails, seed=seed, **{**kw, "max_epochs": cap, "patience": cap}, on_epoch=probe)
    # the stopping curve as train_model saw it: its own losses for epochs >= 0, the probe's for epoch -1
    rec["valid_z"] = [rec["valid_z"][0], *info["valid_loss"]]
    return rec


def scratch_fit(base, heads, tails, seed: int, cap: int, patience: int) -> dict:
    """learn.finetune.train_from_scratch(base.kind, base.hparams, heads, tails, seed, max_epochs=cap, patience=...)
    step by step (Compensator.fit, TorchCompensator._fit), to the cap, probed like one_fit. Scratch has no epoch -1
    candidate: its records start at epoch 0."""
    import torch

    from learn import finetune as FT
    from learn.models.base import make_model
    from learn.normalize import ZScore
    from learn.train import evaluate, seeded, train_model

    t1, t2 = FT.split_tail(tails, 0.5)
    comp = make_model(base.kind, **{**base.hparams, "max_epochs": cap, "patience": patience})
    comp.n_in, comp.n_out = heads[0].x.shape[1], heads[0].y.shape[1]
    comp.inputs, comp.targets, comp.units = list(heads[0].inputs), list(heads[0].targets), dict(heads[0].units)
    comp.x_norm, comp.y_norm = ZScore.fit([s.x for s in heads]), ZScore.fit([s.y for s in heads])
    z = lambda seqs: ([comp.x_norm.apply(s.x) for s in seqs], [comp.y_norm.apply(s.y) for s in seqs])
    zx, zy = z(heads)
    with seeded(seed):
        comp.net = comp._build()
    comp._prepare(zx)
    tr, va, e1 = comp._examples(zx, zy, True), comp._examples(*z(tails), False), comp._examples(*z(t1), False)
    rec: dict[str, list[float]] = {"valid_z": [], "tail_n": [], "t1_z": [], "t2_n": []}

    def probe(epoch: int, net) -> None:
        if epoch < 0:
            return
        with torch.no_grad():
            rec["t1_z"].append(evaluate(net, *e1))
        rec["tail_n"].append(FT.rmse_on(comp, tails))
        rec["t2_n"].append(FT.rmse_on(comp, t2))

    hist = train_model(comp.net, tr, va, comp.train_config(seed), progress=False, description="scratch", on_epoch=probe)
    rec["valid_z"] = list(hist.valid_loss)
    return rec


def score(rec: dict, patience: int, keep_initial: bool = True) -> dict:
    from learn.train import stopping_epoch

    o = 1 if keep_initial else 0  # index of epoch 0 in the records
    e = stopping_epoch(rec["valid_z"], patience, keep_initial)
    e1 = stopping_epoch(rec["t1_z"], patience, keep_initial)
    return {"best_epoch": e, "valid_tail_rmse_n": rec["tail_n"][e + o], "held_out_best_epoch": e1,
            "held_out_second_half_rmse_n": rec["t2_n"][e1 + o]}


def main(argv=None):
    import torch
    from bench_s2r_pipeline_noise import pipeline_seed_args

    from learn import finetune as FT
    from learn.checkpoint import load_checkpoint
    from learn.sim2real import S2R_BUDGET, curve_order

    torch.set_num_threads(1)
    ap = pipeline_seed_args()
    ap.add_argument("--patience", type=int, nargs="+", default=[20, 120], help="the stopping rules replayed")
    ap.add_argument("--scratch", action="store_true", help="also the scratch nets (one set: they do not depend on p)")
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    bm = json.loads((a.base / "metrics.json").read_text())
    B = {**S2R_BUDGET, **bm["budget"]}
    cap = int(B["finetune_epochs"])
    out = json.loads(a.out.read_text()) if a.out.is_file() else {"runs": {}}
    cmd = "python bench/bench_s2r_patience.py " + shlex.join(sys.argv[1:] if argv is None else argv)
    out.update(commands=[*out.get("commands", []), cmd], real=a.real, test_episodes=a.test_episodes, base=str(a.base),
               epoch_cap=cap, patience_replayed=a.patience)
    rate = float(B["fit_rate_hz"])
    seqs = FT.apply_map(FT.load_recording(a.real, ["sensor"], ["force"], rate_hz=rate), "log")
    sp = FT.split_runs(seqs, train_fraction=None, test_glob=a.test_episodes, seed=0, n_valid=0)
    order = curve_order(seqs, a.test_episodes, 0)
    sizes = sorted({k for k in (1, 2, 4) if k < len(sp.train)} | {len(sp.train)})
    seeds = [int(k) for k in range(int(B["n_train_seeds"]))]
    kw = dict(policy=B["policy"], lr=B["lr"], norm=B["finetune_norm"], method="plain")
    if a.scratch and "scratch" not in out:
        base = load_checkpoint(a.base / "checkpoints" / "pretrained")  # its kind and hparams only
        fits, t0 = [], time.perf_counter()
        for k in sizes:
            tr = [s for s in sp.train if s.key in order[:k]]
            heads, tails = FT.split_tail(tr, float(B["valid_tail"]))
            for sd in seeds:
                rec = scratch_fit(base, heads, tails, sd, cap, int(B["finetune_patience"]))
                fits.append({"n_runs": k, "seed": sd, **{f"P{P}": score(rec, P, keep_initial=False) for P in a.patience},
                             "curve": {k2: [round(float(v), 6) for v in vals] for k2, vals in rec.items()}})
                print(f"scratch n={k} seed={sd}: " + ", ".join(f"P{P} {fits[-1][f'P{P}']}" for P in a.patience), flush=True)
        out["scratch"] = {"fits": fits, "seconds": time.perf_counter() - t0,
                          **{f"P{P}": {"valid_tail_mean": float(np.mean([f[f"P{P}"]["valid_tail_rmse_n"] for f in fits])),
                                       "held_out_second_half_mean": float(np.mean([f[f"P{P}"]["held_out_second_half_rmse_n"]
                                                                                   for f in fits]))} for P in a.patience}}
        a.out.write_text(json.dumps(out, indent=1, default=float))
    for p in a.pipeline_seeds:
        key = f"p{p}"
        if key in out["runs"]:
            continue
        ck = a.base / "checkpoints" / "pretrained" if p == 0 else a.work / f"p{p}" / "checkpoints" / "pretrained"
        base = load_checkpoint(ck)
        t0 = time.perf_counter()
        fits = []
        for k in sizes:
            tr = [s for s in sp.train if s.key in order[:k]]
            heads, tails = FT.split_tail(tr, float(B["valid_tail"]))
            for sd in seeds:
                rec = one_fit(base, heads, tails, kw, sd, cap)
                fits.append({"n_runs": k, "seed": sd, **{f"P{P}": score(rec, P) for P in a.patience},
                             "curve": {k2: [round(float(v), 6) for v in vals] for k2, vals in rec.items()}})
                print(f"{key} n={k} seed={sd}: " + ", ".join(f"P{P} {fits[-1][f'P{P}']}" for P in a.patience), flush=True)
        r = {"fits": fits, "seconds": time.perf_counter() - t0}
        for P in a.patience:
            r[f"P{P}"] = {"valid_tail_mean": float(np.mean([f[f"P{P}"]["valid_tail_rmse_n"] for f in fits])),
                          "held_out_second_half_mean": float(np.mean([f[f"P{P}"]["held_out_second_half_rmse_n"] for f in fits]))}
        out["runs"][key] = r
        print(key, {P: r[f"P{P}"] for P in a.patience}, f"{r['seconds']:.0f} s", flush=True)
        a.out.write_text(json.dumps(out, indent=1, default=float))
    out["stats"] = stats(out, a.patience)
    a.out.write_text(json.dumps(out, indent=1, default=float))
    print(json.dumps(out["stats"], indent=1, default=float))


def stats(out: dict, patience: list[int]) -> dict:
    from learn.sim2real import paired_improvement

    ps = sorted(out["runs"])
    if len(ps) < 2 or len(patience) < 2:
        return {}
    ref, cand = f"P{patience[0]}", f"P{patience[1]}"
    g = lambda P, m: [out["runs"][p][P][m] for p in ps]
    return {"pipeline_seeds": ps, "reference": ref, "candidate": cand,
            "valid_tail": paired_improvement(g(ref, "valid_tail_mean"), g(cand, "valid_tail_mean")),
            "held_out_second_half": paired_improvement(g(ref, "held_out_second_half_mean"), g(cand, "held_out_second_half_mean"))}


if __name__ == "__main__":
    main()

"""Why ours (the TCN ensemble) loses the unsigned hold drift to the paper's chains at quick: a decomposition on the
VALIDATION recordings of a finished quick run (its data and checkpoints; nothing here reads the test split).

Per hold of >= 2 s (learn.experiments.velostat.hold_errors' definition: |mean of the last second - mean of the first
second| of the estimate), for ours as trained, ours fed the same recordings through an ideal readout (the true R:
what following the readout noise costs), ours' first member alone (what the ensemble's averaging removes), and the
chains paper_unit and literal_unit: the mean |drift| and signed drift by the contact's age at the hold's start
(0-25 s: inside ours' 25.5 s receptive field; 25-60 s; > 60 s), by force, and the mean error trajectory in the hold.
--variants: ours retrained with another receptive field (dilations to 128: 51 s; chunk 128 or 256) on the same
features, every input set, its validation RMSE and hold drift (the experiment's choice: the lowest validation RMSE).

    PYTHONPATH=. python bench/bench_velostat_hold_drift.py RUN_DIR [--seed 0] [--variants d128c128,d128c256]
writes bench/results/velostat-hold-drift.json (docs/gen renders it on the velostat experiment page).

Session 12's adoption rule (CHANGELOG "velostat, session 12"), from one file per quick seed written with
--variants residual --out bench/results/velostat-residual-seedS.json:
    PYTHONPATH=. python bench/bench_velostat_hold_drift.py --rule residual bench/results/velostat-residual-seed{0,1,2}.json
writes bench/results/velostat-residual-rule.json: per seed today's default and the candidate (validation RMSE, hold
drift), the paired differences' means and standard errors, and whether the rule adopts.

Session 13's candidate (CHANGELOG "velostat, session 13"): --variants sobolev (derivative matching, the TCN's
diff_loss_weight 1 / diff_loss_lag 10 samples, today's residual kept) -> bench/results/velostat-sobolev-seedS.json,
then --rule sobolev -> bench/results/velostat-sobolev-rule.json. A variant without a "residual" key keeps the
experiment's default (Mode.tcn_residual).
"""

from __future__ import annotations

import argparse
import copy
import datetime as dt
import json
import platform
import subprocess
import time
from pathlib import Path

import numpy as np
import torch

VARIANTS = {"d128c128": {"dilations": [1, 2, 4, 8, 16, 32, 64, 128], "chunk": 128},
            "d128c256": {"dilations": [1, 2, 4, 8, 16, 32, 64, 128], "chunk": 256},
            # session 12's candidate: the input sets holding the compensated chain's force learn a correction to it
            "residual": {"residual": "bp_comp_force_n"},
            # session 13's candidate: derivative matching (Sobolev training; Czarnecki et al., NeurIPS 2017): loss
            # MSE + 1.0 * MSE of the 10-sample (1 s at 10 Hz: the hold drift's scale) differences, both fixed a
            # priori (# estimate: not tuned); the residual on the compensated chain as today's default
            "sobolev": {"diff_loss_weight": 1.0, "diff_loss_lag": 10}}
# (every input set is trained: those without the residual channel as the run trained them, same seeds)
AGES_S = ((0.0, 25.0), (25.0, 60.0), (60.0, float("inf")))
FORCES_N = ((0.0, 3.0), (3.0, 8.0), (8.0, 16.0))


def rule(variant: str, files: list[str], out: str) -> dict:
    """The adoption rule on the paired differences d = candidate - default over the seeds' validation recordings:
    adopt if mean(d_drift) < -SE(d_drift) and mean(d_rmse) <= SE(d_rmse), SE = std(d, ddof=1) / sqrt(n)."""
    per = {}
    for f in files:
        d = json.loads(Path(f).read_text())
        v = d["variants"][variant]
        c = v["by_inputs"][v["picked"]]
        per[int(d["seed"])] = {"default": d["default"],
                               "candidate": {"inputs": v["picked"], "valid_rmse": c["valid_rmse"],
                                             "drift_mean": c["drift_mean"], "drift_signed_mean": c["drift_signed_mean"]},
                               "file": f}
    from learn.experiments.velostat import MODES, TCN_INPUTS

    ch = VARIANTS[variant].get("residual", MODES["quick"].tcn_residual)
    res: dict = {"variant": variant, "split": "valid", "mode": "quick", "seeds": per, "differences": {},
                 "residual_input_sets": [v for v, names in TCN_INPUTS.items() if ch in names]}
    ok = {}
    for key in ("drift_mean", "valid_rmse"):
        dd = np.array([p["candidate"][key] - p["default"][key] for p in per.values()])
        se = float(dd.std(ddof=1) / np.sqrt(len(dd))) if len(dd) > 1 else float("nan")
        res["differences"][key] = {"per_seed": dd.tolist(), "mean": float(dd.mean()), "se": se}
        ok[key] = bool(dd.mean() < -se) if key == "drift_mean" else bool(dd.mean() <= se)
    res["conditions"] = {"drift_falls_by_more_than_se": ok["drift_mean"], "rmse_rises_by_at_most_se": ok["valid_rmse"]}
    res["adopted"] = ok["drift_mean"] and ok["valid_rmse"]
    Path(out).write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    return res


def main() -> None:
    from learn import metrics as M
    from learn.checkpoint import load_checkpoint
    from learn.data import stratified_split
    from learn.experiments import velostat as V
    from learn.models.velostat import CreepTracker
    from simulate.protocols.compression_tester import unit_centres_m

    ap = argparse.ArgumentParser()
    ap.add_argument("run", nargs="+")
    ap.add_argument("--rule", default="", help="a variant: apply the adoption rule to the per-seed files given")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variants", default="")
    ap.add_argument("--out", default="bench/results/velostat-hold-drift.json")
    a = ap.parse_args()
    if a.rule:
        rule(a.rule, a.run, a.out if a.out != ap.get_default("out") else f"bench/results/velostat-{a.rule}-rule.json")
        return
    torch.set_num_threads(1)
    run = Path(a.run[0])
    m = json.loads((run / "metrics.json").read_text())
    md = V.MODES[m["mode"]]
    cfgs = V.scenes_of(md, [], a.seed)
    seqs = {n: V._load(run / "data" / n, cfgs[n]) for n in cfgs}
    sp_mix, sp_cal = stratified_split(seqs["mix"], "inner_kind", a.seed), V.calibration_split(seqs["cal"])
    tr, va = sp_mix["train"] + sp_cal["train"], sp_mix["valid"] + sp_cal["valid"]
    if [s.key for s in tr] != m["split"]["train"] or [s.key for s in va] != m["split"]["valid"]:
        raise SystemExit("the split made again differs from the run's")
    cfg = cfgs["mix"]
    rate = cfg.sampling.sample_rate_hz
    ck = run / "checkpoints"
    tracker = CreepTracker.from_state(json.loads((ck / "creep_tracker.json").read_text()))
    near = V.nearest_with_data(np.array(m["clustering"]["units_with_data"]), unit_centres_m(cfg))
    chains = {"raw_bp": V.PaperChain(tracker, load_checkpoint(ck / "raw_bp"), near, cfg, compensate=False),
              "paper_unit": V.PaperChain(tracker, load_checkpoint(ck / "paper_unit"), near, cfg)}
    lit = V.PaperChain(tracker, load_checkpoint(ck / "literal_unit"), None, cfg)
    tcn = load_checkpoint(ck / "tcn")
    inp = m["models"]["tcn"]["inputs"]

    def feats(s):
        return V.tcn_features(s, tracker if inp != "raw" else None, chains if inp in ("calibrated", "aged") else None,
                              rate if inp == "aged" else None)

    def ideal(s):  # the same recording through an ideal readout: the true R_film + R_ITO
        c = copy.copy(s)
        c.x = s.x.copy()
        c.x[:, 0] = s.extra["resistance"]
        return c

    with torch.inference_mode():
        P = {"ours": [tcn.predict(feats(s))[:, 0] for s in va],
             "ours_ideal_readout": [tcn.predict(feats(ideal(s)))[:, 0] for s in va],
             "ours_member0": [tcn.members[0].predict(feats(s))[:, 0] for s in va],
             "paper_unit": [chains["paper_unit"].predict(s) for s in va],
             "literal_unit": [lit.predict(s) for s in va]}
    out: dict = {"run": str(run), "mode": m["mode"], "seed": a.seed, "split": "valid", "ours_inputs": inp,
                 "receptive_field_s": tcn.context / rate, "n_valid_recordings": len(va), "models": {},
                 "ours_residual_input": tcn.members[0].hparams.get("residual_input"),
                 "ours_diff_loss": [float(tcn.members[0].hparams.get("diff_loss_weight") or 0.0),
                                    int(tcn.members[0].hparams.get("diff_loss_lag") or 0)]}
    for k, pr in P.items():
        rows = []
        traj = {f"{lo:g}-{hi:g}": [] for lo, hi in AGES_S}
        for s, p in zip(va, pr):
            age = V.contact_age_s(np.isfinite(s.x[:, 1:3]).all(1), rate)
            for h in V.holds(s.extra["target"], int(2 * rate)):
                n = int(rate)
                rows.append((p[h][-n:].mean() - p[h][:n].mean(), age[h.start], s.extra["target"][h].mean()))
                if h.stop - h.start >= 4 * n:
                    for lo, hi in AGES_S:
                        if lo <= age[h.start] < hi:
                            traj[f"{lo:g}-{hi:g}"].append((p[h] - s.y[h, 0])[: 4 * n])
        r = np.asarray(rows)
        d = r[:, 0]

        def part(mask):
            return {"n_holds": int(mask.sum()), "drift_mean": float(np.abs(d[mask]).mean()),
                    "drift_signed_mean": float(d[mask].mean())} if mask.any() else {"n_holds": 0}
        out["models"][k] = {
            "drift_mean": float(np.abs(d).mean()), "drift_signed_mean": float(d.mean()), "n_holds": len(d),
            "by_contact_age_s": {f"{lo:g}-{hi:g}": part((r[:, 1] >= lo) & (r[:, 1] < hi)) for lo, hi in AGES_S},
            "by_force_n": {f"{lo:g}-{hi:g}": part((r[:, 2] >= lo) & (r[:, 2] < hi)) for lo, hi in FORCES_N},
            "error_trajectory_n": {key: np.mean(v, 0).reshape(8, -1).mean(1).tolist() for key, v in traj.items() if v}}
    out["trajectory_step_s"] = 0.5
    # today's default as the run picked it: what a variant is compared with (the adoption rule, CHANGELOG)
    out["default"] = {"inputs": inp, "valid_rmse": m["models"]["tcn"]["valid_rmse_by_inputs"][inp],
                      "drift_mean": out["models"]["ours"]["drift_mean"],
                      "drift_signed_mean": out["models"]["ours"]["drift_signed_mean"]}
    if a.variants:
        jobs = {"raw": lambda s: V.tcn_features(s), "calibrated": lambda s: V.tcn_features(s, tracker, chains),
                "aged": lambda s: V.tcn_features(s, tracker, chains, rate)}
        F = {v: ([f(s) for s in tr], [s.y for s in tr], [f(s) for s in va], [s.y for s in va]) for v, f in jobs.items()}
        yv = np.concatenate([s.y[:, 0] for s in va])
        out["variants"] = {}
        for name in a.variants.split(","):
            hp = {**md.tcn, **VARIANTS[name]}
            residual = hp.pop("residual", md.tcn_residual)  # none given: the experiment's default
            # every input set, as the experiment trains them (those without the residual channel as they are)
            ens, secs = V._fit_tcn_batched(F, seed=a.seed, n_members=md.tcn_members, member_hparams=hp,
                                           residual=residual)
            res = {}
            for v, e in ens.items():
                with torch.inference_mode():
                    pv = [e.predict(x)[:, 0] for x in F[v][2]]
                h = V.hold_errors(va, pv, rate)
                res[v] = {"valid_rmse": M.rmse(yv, np.concatenate(pv)), "drift_mean": h["drift_mean"],
                          "drift_signed_mean": h["drift_signed_mean"], "epochs": [mm.history["epochs"] for mm in e.members]}
            pick = min(res, key=lambda v: res[v]["valid_rmse"])
            out["variants"][name] = {"hparams": VARIANTS[name], "residual_input": residual,
                                     "receptive_field_s": ens[pick].context / rate,
                                     "fit_seconds": secs, "by_inputs": res, "picked": pick}
            print(name, json.dumps(out["variants"][name]), flush=True)
    prev = Path(a.out)
    if not a.variants and prev.is_file():  # the variants tried before (another model's run) stay on record, marked
        old = json.loads(prev.read_text())
        if old.get("variants"):
            out["variants"] = old["variants"]
            # where they were tried: the old file's own record of it if it already carried them over
            out["variants_from"] = old.get("variants_from") or {
                "run": old.get("run"), "git_commit": old.get("machine", {}).get("git_commit"),
                "ours_inputs": old.get("ours_inputs")}
    out["machine"] = {"host_platform": platform.platform(), "date_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
                      "git_commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                                   text=True).stdout.strip()}
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({k: {kk: vv for kk, vv in v.items() if kk in ("drift_mean", "drift_signed_mean", "by_contact_age_s")}
                      for k, v in out["models"].items()}, indent=1))


if __name__ == "__main__":
    t0 = time.time()
    main()
    print(f"{time.time() - t0:.0f} s")

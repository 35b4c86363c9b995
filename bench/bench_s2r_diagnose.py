"""Why the sim-trained compensator misses on the Lupasic logs zero-shot, measured on a finished
`piezotwin sim2real` folder (its fit.json, sim.h5, pre-trained checkpoint) and the real recording.

    python bench/bench_s2r_diagnose.py RUN_DIR REAL.h5 --test-episodes GLOB [--lr-check] -o bench/results/s2r-diagnosis-<name>.json

Measured (no training unless --lr-check):
  zero-shot on the real readings and on the identified chain's own noise-free reading of the same real force
  histories (level 0): the same error on both says the gap is in what the net learned from the simulated
  data, not in a real-vs-chain mismatch or a level shift of the test series;
  the real press levels against the chain (mean, sd) on the training and the test series;
  the plateau sensitivity -d ln(reading)/d ln(force) over the training runs, real vs chain, and the per-run
  mean level's trend with ln force (what per-press free levels absorb when the law is too flat);
  the simulated spread of the plateau reading at the real force histories (bootstrap replicate; + episode
  gain; + press level), and the force ambiguity it implies for an MSE-trained net: posterior sd of ln F =
  spread / sensitivity, mean / median = exp(sd^2 / 2);
  the identification check: the chain fit with free press levels, with press levels forced to carry no trend in ln
  force (not adopted), and with the level prior (fit_chain level_prior: adopted for the Lupasic board), on the
  training runs and on a synthetic chain of known parameters (tests/test_fit.py's);
  --lr-check: fine-tuning at scratch's learning rate (2e-3) instead of the budget's, same seeds and epochs.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

RATE = 20.0


def _plateaus(f, x, C):
    o = []
    for sl in C.presses_of(f, 0.1 * f.max()):
        h = sl.start + np.flatnonzero(f[sl] >= 0.9 * f[sl].max())
        o.append((float(np.median(f[h])), float(np.median(x[h]))))
    return o


def _independent_levels(C):
    """Patch chain_fit._fit_shape so that the profiled press levels may not trend with ln(peak force)."""
    orig_profile, orig_fit = C._profile, C._fit_shape

    def prof(data, q, idx):
        out, lev = orig_profile(data, q, idx)
        lnf = np.array([np.log(data.runs[data.presses[j].run].force[data.presses[j].sl].max()) for j in idx])
        d = lnf - lnf.mean()
        b = float(np.sum((lev - lev.mean()) * d) / np.sum(d * d)) if np.sum(d * d) > 0 else 0.0
        return [o - b * dd for o, dd in zip(out, d)], lev

    def fit_shape(*a):
        C._profile = prof
        try:
            return orig_fit(*a)
        finally:
            C._profile = orig_profile

    C._fit_shape = fit_shape
    return lambda: setattr(C, "_fit_shape", orig_fit)


def identification_check(recording, test_glob, C) -> dict:
    from learn.sim2real import _chain_prior
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_fit import _synthetic_runs

    out = {}
    runs = C.load_real_runs(recording, rate_hz=RATE)
    train = [r for r in runs if not fnmatch.fnmatch(r.key, test_glob)]
    test = [r for r in runs if fnmatch.fnmatch(r.key, test_glob)]
    true = C.ChainParams(exponent=1.2, r0_ohm=3000.0, creep_amplitude=2.0, creep_force_n=4.0, tau_min_s=0.1, tau_max_s=5.0,
                         n_creep=4, level_log_sd=0.4, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0)
    syn, syn_new = _synthetic_runs(true), _synthetic_runs(true, n_runs=4, seed=7)
    for mode in ("free_levels", "levels_without_force_trend", "level_prior"):
        undo = _independent_levels(C) if mode == "levels_without_force_trend" else (lambda: None)
        try:
            lp = mode == "level_prior"
            fit = C.fit_chain(train, _chain_prior("velostat", runs), n_boot=0, level_prior=lp)
            held = C.evaluate(fit, test)
            sfit = C.fit_chain(syn, C.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4), n_boot=0, level_prior=lp)
        finally:
            undo()
        q = replace(sfit.params, noise_sd=0.0, level_log_sd=0.0)
        t0 = replace(true, level_log_sd=0.0)
        e = []
        for r in syn_new:
            yt, yf = np.log(C.simulate_reading(r.force, r.dt, t0)), np.log(C.simulate_reading(r.force, r.dt, q))
            e += [b - a for (_, a), (_, b) in zip(_plateaus(r.force, yt, C), _plateaus(r.force, yf, C))]
        p = fit.params
        out[mode] = {"lupasic_params": {k: getattr(p, k) for k in ("exponent", "creep_amplitude", "creep_force_n", "tau_min_s", "tau_max_s", "level_log_sd")},
                     "lupasic_within_press_fit": fit.error["rms_log_reading_within_press"],
                     "lupasic_held_out_within_press": held.get("rms_log_reading_within_press"),
                     "lupasic_held_out_level_in_band90": held.get("level_in_band90"),
                     "synthetic_exponent_true_1.2": sfit.params.exponent,
                     "synthetic_plateau_error_sd_ln": float(np.std(e)), "synthetic_plateau_error_mean_ln": float(np.mean(e))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run_dir")
    ap.add_argument("recording")
    ap.add_argument("--test-episodes", required=True)
    ap.add_argument("--lr-check", action="store_true")
    ap.add_argument("-o", "--out", required=True)
    a = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from learn import finetune as FT
    from learn.checkpoint import load_checkpoint
    from learn.data import Sequence
    from scenes.randomize import Randomization, draw
    from sensors import chain_fit as C

    t0 = time.perf_counter()
    d = Path(a.run_dir)
    seqs = FT.apply_map(FT.load_recording(a.recording, ["sensor"], ["force"], rate_hz=RATE), "log")
    sp = FT.split_runs(seqs, train_fraction=None, test_glob=a.test_episodes, seed=0)
    base = load_checkpoint(d / "checkpoints" / "pretrained")
    p, fj = C.load_params(d / "fit.json")
    q = replace(p, noise_sd=0.0, miss_prob=0.0)
    rand = Randomization.model_validate(fj["randomization"])
    R: dict = {"run_dir": str(d), "test_episodes": a.test_episodes,
               "chain": {k: getattr(p, k) for k in ("exponent", "r0_ohm", "creep_amplitude", "creep_force_n", "tau_min_s", "tau_max_s", "level_log_sd")},
               "episode_gain_log_sd": fj["randomization"]["episode"]["gain_log"]["sd"]}

    def ev(S):
        y = np.concatenate([s.y[:, 0] for s in S])
        e = np.concatenate([base.predict(s.x)[:, 0] for s in S])
        ld = y > 0.1 * y.max()
        return {"rmse_n": float(np.sqrt(np.mean((e - y) ** 2))), "bias_loaded_n": float(np.mean((e - y)[ld])),
                "median_ratio_loaded": float(np.median(e[ld] / y[ld]))}

    def chain_reading(S):
        return [Sequence(np.log(C.simulate_reading(s.y[:, 0], 1 / RATE, q))[:, None], s.y, s.inputs, s.targets, s.units, s.meta, s.extra) for s in S]

    for part in ("train", "test"):
        S = getattr(sp, part)
        ch = chain_reading(S)
        R[f"zero_shot_real_{part}"] = ev(S)
        R[f"zero_shot_chain_reading_{part}"] = ev(ch)
        lev = [b[1] - c[1] for s, cs in zip(S, ch) for b, c in zip(_plateaus(s.y[:, 0], s.x[:, 0], C), _plateaus(cs.y[:, 0], cs.x[:, 0], C))]
        R[f"real_level_vs_chain_{part}"] = {"mean_ln": float(np.mean(lev)), "sd_ln": float(np.std(lev)), "n_presses": len(lev)}
    rows = []
    for s, c in zip(sp.train, chain_reading(sp.train)):
        pr, pc = _plateaus(s.y[:, 0], s.x[:, 0], C), _plateaus(c.y[:, 0], c.x[:, 0], C)
        rows.append({"run": s.key, "plateau_force_n": float(np.median([u for u, _ in pr])), "ln_reading_real": float(np.median([v for _, v in pr])),
                     "ln_reading_chain": float(np.median([v for _, v in pc])), "level_mean_ln": float(np.mean([u[1] - v[1] for u, v in zip(pr, pc)]))})
    R["runs"] = rows
    lf = np.log([r["plateau_force_n"] for r in rows])
    if len(rows) >= 3 and np.ptp(lf) >= np.log(2.0):
        R["plateau_sensitivity"] = {"real": float(-np.polyfit(lf, [r["ln_reading_real"] for r in rows], 1)[0]),
                                    "chain": float(-np.polyfit(lf, [r["ln_reading_chain"] for r in rows], 1)[0]),
                                    "run_level_trend_per_ln_force": float(np.polyfit(lf, [r["level_mean_ln"] for r in rows], 1)[0])}
    else:  # the training runs do not span a force range (pike2: one run, presses of about 21 N)
        R["plateau_sensitivity"] = {"real": None, "chain": None, "run_level_trend_per_ln_force": None,
                                    "note": f"{len(rows)} training run(s) spanning a factor {float(np.exp(np.ptp(lf))):.2f} in force"}
    comp: dict[str, list[float]] = {"replicate": [], "replicate_gain": [], "replicate_gain_press_level": []}
    for k in range(24):
        vals, rng = draw(rand, 1000 + k)
        qq = replace(q)
        for kk in ("exponent", "creep_amplitude", "creep_force_n", "tau_min_s", "tau_max_s", "level_log_sd", "r_series_ohm",
                   "threshold_force_n", "r0_ohm"):
            if kk in vals:
                setattr(qq, kk, float(vals[kk]))
        g = float(vals.get("gain_log", 0.0))
        for name, lsd, gg in (("replicate", 0.0, 0.0), ("replicate_gain", 0.0, g), ("replicate_gain_press_level", qq.level_log_sd, g)):
            for s in sp.train[:6]:
                f = s.y[:, 0]
                x0 = np.log(C.simulate_reading(f, 1 / RATE, q))
                lv = np.zeros(len(f))
                for sl in C.presses_of(f, 0.1 * f.max()):
                    lv[sl] = rng.normal(0, lsd)
                x = np.log(C.simulate_reading(f, 1 / RATE, qq, level=lv + gg))
                comp[name] += [b[1] - a0[1] for a0, b in zip(_plateaus(f, x0, C), _plateaus(f, x, C))]
    R["sim_spread_at_real_forces_sd_ln"] = {k: float(np.std(v)) for k, v in comp.items()}
    sens = R["plateau_sensitivity"]["chain"]
    sig = R["sim_spread_at_real_forces_sd_ln"]["replicate_gain_press_level"] / sens if sens else None
    R["implied_by_sim_spread"] = {"ln_force_posterior_sd": sig, "mean_over_median": float(np.exp(sig ** 2 / 2)) if sig else None}
    R["identification_check"] = identification_check(a.recording, a.test_episodes, C)
    if a.lr_check:
        kw = dict(policy="none", max_epochs=120, patience=20, norm="checkpoint")
        lc = {}
        for k in sorted({2, len(sp.train)}):
            tr = [s for s in sp.train if s.key in sp.order[:k]]
            lc[str(k)] = {f"{lr:g}": [FT.rmse_on(FT.finetune(base, tr, sp.valid, lr=lr, seed=sd, **kw)[0], sp.test) for sd in (0, 1, 2)]
                          for lr in (3e-4, 2e-3)}
        R["lr_check_test_rmse_n"] = lc
    R["seconds"] = time.perf_counter() - t0
    R["machine"] = {"cpus": os.cpu_count(), "loadavg": os.getloadavg()}
    Path(a.out).write_text(json.dumps(R, indent=1, default=float))
    print(json.dumps({k: v for k, v in R.items() if k != "runs"}, indent=1, default=float))


if __name__ == "__main__":
    main()

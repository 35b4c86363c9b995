"""Where the fitted chain's force law goes flat on the Lupasic logs, measured model-free and with two creep laws.

    python bench/bench_s2r_identify.py REAL.h5 --test-episodes GLOB -o bench/results/s2r-identification-<name>.json

Model-free, on ln R (the film resistance through the inverse divider, reference 10 kOhm, full scale = the run's
rest level; sensors/chain_fit.py), per press of every run (loaded stretch as chain_fit._Data):
  ramp slope: d ln R / d ln F over the loading ramp from 30 % to 90 % of the peak (least squares);
  across-press slope: the presses' plateau median ln R against their ln plateau force (all presses; run means);
  the hold: ln R on the plateau (>= 90 % of peak) regressed on ln F and ln(1 + t / 0.05 s) jointly: a creep that
  follows log time (contact aging, Dieterich & Kilgore 1994) shows in the second coefficient, a force-law
  effect in the first.
Per press also a local fit, ln R on [1, ln F, ln(1 + t / 0.05 s)] over its ramp and hold (a press's own power law
and log-time creep): the spread of the presses' slopes within a run and its regression on the press level, and the
local fit's residual variance against the rate |d ln F / dt| (e^2 = floor^2 + (s_t rate)^2 on ten quantile bins): a
timing error s_t between the two streams would show there as errors in variables on the fast ramps.
Chain fits on the training runs (no bootstrap), creep_law "force" (the default) and "aging", free press levels and
the level prior (fit_chain level_prior): parameters,
within-press error, held-out press levels, and the plateau sensitivity -d ln(reading) / d ln F of the run medians,
real vs the chain's noise-free reading at level 0, with the run-mean level trend per ln F (what free press levels
absorb when the law is too flat; bench/bench_s2r_diagnose.py's definition).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

RATE = 20.0
T0_S = 0.05  # estimate: one sample at 20 Hz, the earliest time a hold is resolved


def model_free(runs, C) -> dict:
    p = C.ChainParams(divider="high", r_ref_ohm=1e4)
    rows = []
    for r in runs:
        lnr = np.log(C.resistance_from_reading(r.reading, p, r.fs))
        for sl in C.presses_of(r.force, max(0.1 * r.force.max(), 0.05)):
            seg = np.arange(sl.start, sl.stop)
            f = r.force[seg]
            ipk = np.flatnonzero(f >= 0.9 * f.max())
            ramp = seg[: ipk[0] + 1]
            ramp = ramp[r.force[ramp] > 0.3 * f.max()]
            hold = seg[ipk[0]: ipk[-1] + 1]
            if len(hold) < 8 or not np.all(np.isfinite(lnr[seg])):
                continue
            x = np.log(r.force[ramp])
            s = float(np.polyfit(x, lnr[ramp], 1)[0]) if len(ramp) >= 3 and np.ptp(x) > 0.3 else float("nan")
            lf = np.log(r.force[hold])
            X = np.c_[np.ones(len(hold)), lf - lf.mean(), np.log1p(np.arange(len(hold)) * r.dt / T0_S)]
            b = np.linalg.lstsq(X, lnr[hold], rcond=None)[0]
            loc = seg[r.force[seg] > 0.3 * f.max()]
            loc = loc[: np.flatnonzero(r.force[loc] >= 0.9 * f.max())[-1] + 1]
            lf2 = np.log(r.force[loc])
            A = np.c_[np.ones(len(loc)), lf2, np.log1p(np.arange(len(loc)) * r.dt / T0_S)]
            cl = np.linalg.lstsq(A, lnr[loc], rcond=None)[0]
            e = lnr[loc] - A @ cl
            rate = np.abs(np.gradient(np.log(np.maximum(r.force, 1e-9)))[loc]) / r.dt
            rows.append(dict(run=r.key, ln_plateau_force=float(np.median(lf)), ln_plateau_r=float(np.median(lnr[hold])),
                             ramp_slope=s, hold_dlnr_dlnf=float(b[1]), hold_dlnr_dlnt=float(b[2]),
                             hold_s=float(len(hold) * r.dt), hold_dlnr=float(lnr[hold[-1]] - lnr[hold[0]]),
                             hold_dlnf=float(lf[-1] - lf[0]), local_slope=float(cl[1]),
                             local_e2=(e ** 2 * len(e) / max(len(e) - 3, 1)).tolist(), local_rate=rate.tolist()))
    per_run = {}
    for k in dict.fromkeys(r["run"] for r in rows):
        a = [r for r in rows if r["run"] == k]
        per_run[k] = {"n_presses": len(a), **{f: float(np.nanmedian([r[f] for r in a])) for f in
                                                  ("ramp_slope", "hold_dlnr_dlnf", "hold_dlnr_dlnt", "hold_s", "hold_dlnr", "hold_dlnf")},
                      "ln_plateau_force_mean": float(np.mean([r["ln_plateau_force"] for r in a])),
                      "ln_plateau_r_mean": float(np.mean([r["ln_plateau_r"] for r in a])),
                      "ln_plateau_r_sd": float(np.std([r["ln_plateau_r"] for r in a]))}
    # per-press slopes within runs (run means removed), against the press level at the run's common slope
    ds, dl = [], []
    for k in per_run:
        a = [r for r in rows if r["run"] == k]
        if len(a) < 4:
            continue
        sl = np.array([r["local_slope"] for r in a])
        lv = np.array([r["ln_plateau_r"] for r in a]) - np.polyfit([r["ln_plateau_force"] for r in a], [r["ln_plateau_r"] for r in a], 0)[0]
        ds.extend(sl - sl.mean())
        dl.extend(lv - lv.mean())
    ds, dl = np.array(ds), np.array(dl)
    e2 = np.concatenate([r["local_e2"] for r in rows])
    g2 = np.concatenate([r["local_rate"] for r in rows]) ** 2
    edges = np.unique(np.quantile(g2, np.linspace(0, 1, 11)))
    b = np.clip(np.searchsorted(edges, g2, side="right") - 1, 0, len(edges) - 2)
    bins = [{"rate_per_s": float(np.sqrt(np.median(g2[b == k]))), "sd_log": float(np.sqrt(np.median(e2[b == k]) / 0.455)),
             "n": int(np.sum(b == k))} for k in range(len(edges) - 1) if np.sum(b == k) >= 10]
    c = np.linalg.lstsq(np.c_[np.ones(len(bins)), [x["rate_per_s"] ** 2 for x in bins]], [x["sd_log"] ** 2 for x in bins], rcond=None)[0]
    for r in rows:
        del r["local_e2"], r["local_rate"]
    local = {"slope_sd_within_run": float(np.std(ds, ddof=1)), "slope_vs_level": float(np.polyfit(dl, ds, 1)[0]),
             "slope_level_corr": float(np.corrcoef(ds, dl)[0, 1]), "n_presses": len(ds),
             "residual_by_rate": bins, "floor_sd_log": float(np.sqrt(max(c[0], 0.0))), "timing_sd_s": float(np.sqrt(max(c[1], 0.0)))}
    return {"rows": rows, "per_run": per_run, "local": local}


def across(rows, keys) -> dict:
    a = [r for r in rows if r["run"] in keys]
    lf, lr = np.array([r["ln_plateau_force"] for r in a]), np.array([r["ln_plateau_r"] for r in a])
    m = np.array([[np.mean([r["ln_plateau_force"] for r in a if r["run"] == k]), np.mean([r["ln_plateau_r"] for r in a if r["run"] == k])] for k in keys])
    return {"across_press_dlnr_dlnf": float(np.polyfit(lf, lr, 1)[0]) if np.ptp(lf) > 0.3 else None,
            "run_mean_dlnr_dlnf": float(np.polyfit(m[:, 0], m[:, 1], 1)[0]) if np.ptp(m[:, 0]) > 0.3 else None,
            "ramp_slope_median": float(np.nanmedian([r["ramp_slope"] for r in a])),
            "hold_dlnr_dlnf_median": float(np.median([r["hold_dlnr_dlnf"] for r in a])),
            "hold_dlnr_dlnt_median": float(np.median([r["hold_dlnr_dlnt"] for r in a])), "n_presses": len(a)}


def fit_law(law, train, test, all_runs, C, level_prior=False) -> dict:
    from learn.sim2real import _chain_prior

    p0 = replace(_chain_prior("velostat", all_runs), creep_law=law)
    t = time.time()
    fit = C.fit_chain(train, p0, n_boot=0, level_prior=level_prior)
    p = fit.params
    held = C.evaluate(fit, test)
    q = replace(p, noise_sd=0.0, miss_prob=0.0)
    F, X, XC, LV = [], [], [], []
    for r in train:
        f, x, xc = r.force, np.log(r.reading), np.log(C.simulate_reading(r.force, r.dt, q))
        lv, ff, xx, cc = [], [], [], []
        for sl in C.presses_of(f, 0.1 * f.max()):
            h = sl.start + np.flatnonzero(f[sl] >= 0.9 * f[sl].max())
            lv.append(np.median(x[h] - xc[h]))
            ff.append(np.median(f[h]))
            xx.append(np.median(x[h]))
            cc.append(np.median(xc[h]))
        F.append(np.log(np.median(ff)))
        X.append(np.median(xx))
        XC.append(np.median(cc))
        LV.append(np.mean(lv))
    return {"creep_law": law, "level_prior": level_prior, "fit_s": time.time() - t,
            "params": {k: getattr(p, k) for k in ("exponent", "r0_ohm", "creep_amplitude", "creep_force_n", "tau_min_s", "tau_max_s", "level_log_sd")},
            "within_press_rms_log_reading": fit.error["rms_log_reading_within_press"],
            "held_out": {k: held[k] for k in ("rms_log_reading_within_press", "level_in_band90", "level_mean_log_vs_fit", "level_sd_log", "plateau_drop")},
            "plateau_sensitivity_real": float(-np.polyfit(F, X, 1)[0]), "plateau_sensitivity_chain": float(-np.polyfit(F, XC, 1)[0]),
            "run_level_trend_per_ln_force": float(np.polyfit(F, LV, 1)[0])}


def main(argv=None):
    from sensors import chain_fit as C

    ap = argparse.ArgumentParser()
    ap.add_argument("real")
    ap.add_argument("--test-episodes", required=True)
    ap.add_argument("-o", "--out", required=True)
    a = ap.parse_args(argv)
    runs = C.load_real_runs(a.real, rate_hz=RATE)
    train = [r for r in runs if not fnmatch.fnmatch(r.key, a.test_episodes)]
    test = [r for r in runs if fnmatch.fnmatch(r.key, a.test_episodes)]
    mf = model_free(runs, C)
    out = {"real": str(a.real), "test_episodes": a.test_episodes, "hold_time_origin_s": T0_S,
           "train": across(mf["rows"], [r.key for r in train]), "test": across(mf["rows"], [r.key for r in test]),
           "per_press_local_fit": mf["local"], "per_run": mf["per_run"], "fits": [fit_law(law, train, test, runs, C, lp) for lp in (False, True) for law in ("force", "aging")]}
    Path(a.out).write_text(json.dumps(out, indent=1, default=float))
    print(json.dumps({k: out[k] for k in ("train", "test", "per_press_local_fit")}, indent=1))
    for f in out["fits"]:
        print(f["creep_law"], f["level_prior"], {k: f[k] for k in ("params", "within_press_rms_log_reading", "plateau_sensitivity_real", "plateau_sensitivity_chain", "run_level_trend_per_ln_force")})


if __name__ == "__main__":
    main()

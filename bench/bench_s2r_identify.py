"""Where the fitted chain's force law goes flat on the Lupasic logs, measured model-free and with two creep laws.

    python bench/bench_s2r_identify.py REAL.h5 --test-episodes GLOB -o bench/results/s2r-identification-<name>.json

Model-free, on ln R (the film resistance through the inverse divider, reference 10 kOhm, full scale = the run's
rest level; sensors/chain_fit.py), per press of every run (loaded stretch as chain_fit._Data):
  ramp slope: d ln R / d ln F over the loading ramp from 30 % to 90 % of the peak (least squares);
  across-press slope: the presses' plateau median ln R against their ln plateau force (all presses; run means);
  the hold: ln R on the plateau (>= 90 % of peak) regressed on ln F and ln(1 + t / 0.05 s) jointly: a creep that
  follows log time (contact aging, Dieterich & Kilgore 1994) shows in the second coefficient, a force-law
  effect in the first.
Chain fits on the training runs (no bootstrap), creep_law "force" (the default) and "aging": parameters,
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
            rows.append(dict(run=r.key, ln_plateau_force=float(np.median(lf)), ln_plateau_r=float(np.median(lnr[hold])),
                             ramp_slope=s, hold_dlnr_dlnf=float(b[1]), hold_dlnr_dlnt=float(b[2]),
                             hold_s=float(len(hold) * r.dt), hold_dlnr=float(lnr[hold[-1]] - lnr[hold[0]]),
                             hold_dlnf=float(lf[-1] - lf[0])))
    per_run = {}
    for k in dict.fromkeys(r["run"] for r in rows):
        a = [r for r in rows if r["run"] == k]
        per_run[k] = {"n_presses": len(a), **{f: float(np.nanmedian([r[f] for r in a])) for f in
                                                  ("ramp_slope", "hold_dlnr_dlnf", "hold_dlnr_dlnt", "hold_s", "hold_dlnr", "hold_dlnf")},
                      "ln_plateau_force_mean": float(np.mean([r["ln_plateau_force"] for r in a])),
                      "ln_plateau_r_mean": float(np.mean([r["ln_plateau_r"] for r in a])),
                      "ln_plateau_r_sd": float(np.std([r["ln_plateau_r"] for r in a]))}
    return {"rows": rows, "per_run": per_run}


def across(rows, keys) -> dict:
    a = [r for r in rows if r["run"] in keys]
    lf, lr = np.array([r["ln_plateau_force"] for r in a]), np.array([r["ln_plateau_r"] for r in a])
    m = np.array([[np.mean([r["ln_plateau_force"] for r in a if r["run"] == k]), np.mean([r["ln_plateau_r"] for r in a if r["run"] == k])] for k in keys])
    return {"across_press_dlnr_dlnf": float(np.polyfit(lf, lr, 1)[0]) if np.ptp(lf) > 0.3 else None,
            "run_mean_dlnr_dlnf": float(np.polyfit(m[:, 0], m[:, 1], 1)[0]) if np.ptp(m[:, 0]) > 0.3 else None,
            "ramp_slope_median": float(np.nanmedian([r["ramp_slope"] for r in a])),
            "hold_dlnr_dlnf_median": float(np.median([r["hold_dlnr_dlnf"] for r in a])),
            "hold_dlnr_dlnt_median": float(np.median([r["hold_dlnr_dlnt"] for r in a])), "n_presses": len(a)}


def fit_law(law, train, test, all_runs, C) -> dict:
    from learn.sim2real import _chain_prior

    p0 = replace(_chain_prior("velostat", all_runs), creep_law=law)
    t = time.time()
    fit = C.fit_chain(train, p0, n_boot=0)
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
    return {"creep_law": law, "fit_s": time.time() - t,
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
           "per_run": mf["per_run"], "fits": [fit_law(law, train, test, runs, C) for law in ("force", "aging")]}
    Path(a.out).write_text(json.dumps(out, indent=1, default=float))
    print(json.dumps({k: out[k] for k in ("train", "test")}, indent=1))
    for f in out["fits"]:
        print(f["creep_law"], {k: f[k] for k in ("params", "within_press_rms_log_reading", "plateau_sensitivity_real", "plateau_sensitivity_chain", "run_level_trend_per_ln_force")})


if __name__ == "__main__":
    main()

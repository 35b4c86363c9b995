"""Why the training run means trend with force, and whether a threshold / linear creep fixes it (seventh round).

    python bench/bench_s2r_force_law.py REAL.h5 --test-episodes GLOB --reference RUN --arm A=RUN --arm B=RUN \
        -o bench/results/s2r-force-law-<split>.json

Each RUN is a `sim2real` folder of the same split (same code, seeds and budget but the fit options recorded in its
metrics.json budget: `fit_threshold`, `creep_linear`). Per RUN, on the TRAINING runs only (the fitted chain of
fit.json, the press levels it profiled):
  the press levels (ln, relative to ln r0) against each press's ln plateau force (median over >= 90 % of its peak):
  the slope over presses and over run means (what the levels absorb of the force law), the run-mean table;
  the chain's steady-state (full creep) local law d ln R / d ln F between 1, 2, 5, 10, 20, 40 N against the
  model-free run-mean law of the real training runs (median ln R on the plateau vs ln plateau force, between
  neighbouring target forces; ln R through the inverse divider as sensors/chain_fit.py);
  the fine-tuned RMSE on the training runs' validation tails (mean over budgets and seeds) and, beside it (never
  used to choose), the test numbers.
The rule (CHANGELOG, seventh round, written before scoring): adopt an arm if the pike1 training fit's run-mean
trend shrinks in magnitude, its validation-tail mean is <= the reference's in BOTH Lupasic directions, and
tests/test_fit.py recovers the known chain; A and B both passing: B only if its tails are <= A's in both directions.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from bench_s2r_press_slope import summary

FORCES_N = (1.0, 2.0, 5.0, 10.0, 20.0, 40.0)


def training_levels(run: Path, real: str, test_glob: str, C) -> dict:
    from learn.sim2real import _chain_prior

    fj = json.loads((run / "fit.json").read_text())
    m = json.loads((run / "metrics.json").read_text())
    p = C.ChainParams.from_json(fj["params"])
    runs = C.load_real_runs(real, rate_hz=float(m["budget"]["fit_rate_hz"]))
    train = [r for r in runs if r.key in fj["fit_runs"]]
    assert not any(fnmatch.fnmatch(r.key, test_glob) for r in train)
    p0 = _chain_prior("velostat", runs)
    data = C._Data(train, replace(p0, r_leak_ohm=C.leak_from_unloaded(train, p0)), 0.1, 0.05)
    lev = np.asarray(fj["press_levels_log"])
    assert len(lev) == len(data.presses), (len(lev), len(data.presses))
    run_of = np.array([pr.run for pr in data.presses])
    lnf, lnr = [], []
    for pr, lr in zip(data.presses, data.lnr):
        f = train[pr.run].force[pr.sl]
        h = f >= 0.9 * f.max()
        lnf.append(float(np.log(np.median(f[h]))))
        lnr.append(float(np.nanmedian(lr[h])))
    lnf, lnr = np.array(lnf), np.array(lnr)
    table = [{"run": train[r].key, "n_presses": int(np.sum(run_of == r)), "ln_plateau_force": float(lnf[run_of == r].mean()),
              "ln_r_real": float(lnr[run_of == r].mean()), "level_mean_log": float(lev[run_of == r].mean())}
             for r in np.unique(run_of)]
    rm = np.array([[t["ln_plateau_force"], t["level_mean_log"]] for t in table])
    varies = np.ptp(lnf) > 0.3
    q = replace(p, r0_ohm=1.0)
    ss = [float(np.log(C.film_resistance(np.full(4000, f), 0.05, q)[-1])) for f in FORCES_N]
    return {"params": {k: fj["params"][k] for k in ("exponent", "r0_ohm", "threshold_force_n", "creep_amplitude", "creep_force_n",
                                                     "tau_min_s", "tau_max_s", "level_log_sd", "r_series_ohm")},
            "within_press_rms_log_reading": fj["error"]["rms_log_reading_within_press"],
            "held_out": {k: fj["held_out"].get(k) for k in ("rms_log_reading_within_press", "level_in_band90", "level_mean_log_vs_fit")},
            "press_level_trend_per_ln_force": float(np.polyfit(lnf, lev, 1)[0]) if varies else None,
            "run_mean_level_trend_per_ln_force": float(np.polyfit(rm[:, 0], rm[:, 1], 1)[0]) if np.ptp(rm[:, 0]) > 0.3 else None,
            "run_means": table,
            "chain_steady_dlnr_dlnf": [{"from_n": a, "to_n": b, "slope": float((y - x) / np.log(b / a))}
                                       for a, b, x, y in zip(FORCES_N[:-1], FORCES_N[1:], ss[:-1], ss[1:])],
            "_lnf_lnr": (lnf, lnr, run_of)}


def real_law(lv: dict) -> list[dict]:
    """Model-free: run means of the plateau ln R pooled per target force (runs within 0.2 ln F), neighbours' slope."""
    lnf, lnr, run_of = lv.pop("_lnf_lnr")
    pts = sorted((float(lnf[run_of == r].mean()), float(lnr[run_of == r].mean())) for r in np.unique(run_of))
    groups: list[list[tuple[float, float]]] = []
    for x in pts:
        if groups and x[0] - groups[-1][-1][0] < 0.2:
            groups[-1].append(x)
        else:
            groups.append([x])
    g = [(float(np.mean([a for a, _ in gr])), float(np.mean([b for _, b in gr]))) for gr in groups]
    return [{"from_n": float(np.exp(a[0])), "to_n": float(np.exp(b[0])), "slope": (b[1] - a[1]) / (b[0] - a[0])}
            for a, b in zip(g[:-1], g[1:])]


def main(argv=None):
    from sensors import chain_fit as C

    ap = argparse.ArgumentParser()
    ap.add_argument("real")
    ap.add_argument("--test-episodes", required=True)
    ap.add_argument("--reference", required=True, type=Path)
    ap.add_argument("--arm", action="append", default=[], help="NAME=RUN")
    ap.add_argument("--series-check", action="store_true", help="also fit r_series + F_0 (fit_series) on the training "
                    "runs from 0 and 20 ohm (no bootstrap): does the readout show a floor?")
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    sides = {"reference": a.reference} | {s.split("=", 1)[0]: Path(s.split("=", 1)[1]) for s in a.arm}
    import shlex
    import sys

    out = {"command": "python bench/bench_s2r_force_law.py " + shlex.join(sys.argv[1:] if argv is None else argv),
           "real": a.real, "test_episodes": a.test_episodes, "sides": {}}
    for name, run in sides.items():
        m = json.loads((run / "metrics.json").read_text())
        lv = training_levels(run, a.real, a.test_episodes, C)
        law = real_law(lv)
        out["sides"][name] = {"fit_threshold": bool(m["budget"].get("fit_threshold")), "creep_linear": bool(m["budget"].get("creep_linear")),
                              "command": m.get("command"), "training_fit": lv, "summary": summary(run),
                              "test_pooled_pct_fs": m["results"]["finetuned"].get("rmse_pct_full_scale")}
        out["real_training_run_mean_dlnr_dlnf"] = law
    ref = out["sides"]["reference"]
    for name, s in out["sides"].items():
        if name == "reference":
            continue
        t0, t1 = ref["training_fit"]["run_mean_level_trend_per_ln_force"], s["training_fit"]["run_mean_level_trend_per_ln_force"]
        s["trend_shrinks"] = None if t0 is None or t1 is None else abs(t1) < abs(t0)
        s["valid_not_worse"] = s["summary"]["finetuned_valid_rmse_mean"] <= ref["summary"]["finetuned_valid_rmse_mean"]
    out["rule"] = ("adopt an arm if the pike1 training fit's run-mean level trend vs ln force shrinks in magnitude, the fine-tuned "
                   "validation-tail RMSE (mean over budgets and seeds) is <= the reference's in both Lupasic directions, and "
                   "tests/test_fit.py recovers the known chain; A and B both passing: B only if its tails are <= A's in both "
                   "directions (test numbers reported, unused)")
    if a.series_check:
        from learn.sim2real import _chain_prior

        runs = C.load_real_runs(a.real, rate_hz=20.0)
        train = [r for r in runs if not fnmatch.fnmatch(r.key, a.test_episodes)]
        out["series_check"] = []
        for r_s in (0.0, 20.0):
            f = C.fit_chain(train, replace(_chain_prior("velostat", runs), r_series_ohm=r_s), n_boot=0, level_prior=True,
                            fit_series=True)
            out["series_check"].append({"start_r_series_ohm": r_s, "r_series_ohm": f.params.r_series_ohm,
                                        "threshold_force_n": f.params.threshold_force_n, "exponent": f.params.exponent,
                                        "within_press_rms_log_reading": f.error["rms_log_reading_within_press"]})
        print("series check", out["series_check"])
    a.out.write_text(json.dumps(out, indent=1, default=float))
    for name, s in out["sides"].items():
        print(name, {k: s["training_fit"][k] for k in ("run_mean_level_trend_per_ln_force", "press_level_trend_per_ln_force", "within_press_rms_log_reading")},
              "valid", round(s["summary"]["finetuned_valid_rmse_mean"], 4), {k: s.get(k) for k in ("trend_shrinks", "valid_not_worse")})


if __name__ == "__main__":
    main()

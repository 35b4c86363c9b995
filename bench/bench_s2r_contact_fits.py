"""The contact-area term on every split's training fit, no bootstrap (ninth round of issue 15).

    python bench/bench_s2r_contact_fits.py LUPASIC.h5 TAMS.h5 -o bench/results/s2r-contact-fits.json

Per split (the five of the sim2real results: Lupasic pike1 -> pike2 and back, TAMS each cover held out) the chain
fitted as `sim2real` fits it (the Lupasic board with the level prior, TAMS with its series resistance and threshold)
without and with `fit_contact`: F_a, exponent, the within-press rms ln reading on the training presses, and beside
them, on the held-out runs (sensors.chain_fit.evaluate, never used to choose), the within-press rms, the levels'
mean offset and the share inside the fitted 90 % band. One point fit each (n_boot 0): the band uses the point fit.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import shlex
import sys
from pathlib import Path

SPLITS = (("pike1-to-pike2", "lupasic", "velostat", "*pike2*"), ("pike2-to-pike1", "lupasic", "velostat", "*pike1*"),
          ("tams-nosil", "tams", "divider", "*-nosil-*"), ("tams-thinsil", "tams", "divider", "*-thinsil-*"),
          ("tams-thicksil", "tams", "divider", "*-thicksil-*"))


def main(argv=None):
    from learn.sim2real import _chain_prior
    from sensors import chain_fit as C

    ap = argparse.ArgumentParser()
    ap.add_argument("lupasic")
    ap.add_argument("tams")
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    out = {"command": "python bench/bench_s2r_contact_fits.py " + shlex.join(sys.argv[1:] if argv is None else argv), "splits": {}}
    for name, rec, fam, glob in SPLITS:
        runs = C.load_real_runs(a.lupasic if rec == "lupasic" else a.tams, rate_hz=20.0)
        train = [r for r in runs if not fnmatch.fnmatch(r.key, glob)]
        test = [r for r in runs if fnmatch.fnmatch(r.key, glob)]
        lp = not any(r.attrs.get("adc_full_scale") for r in runs)
        out["splits"][name] = {}
        for side, fc in (("reference", False), ("contact", True)):
            fit = C.fit_chain(train, _chain_prior(fam, runs), n_boot=0, level_prior=lp, fit_contact=fc)
            q, ev = fit.params, C.evaluate(fit, test)
            out["splits"][name][side] = {
                "exponent": q.exponent, "contact_force_n": q.contact_force_n, "threshold_force_n": q.threshold_force_n,
                "creep_amplitude": q.creep_amplitude, "creep_force_n": q.creep_force_n,
                "within_press_rms_log_reading": fit.error["rms_log_reading_within_press"], "level_log_sd": q.level_log_sd,
                "at_bound": [n for n, v, lo, hi in zip(C.NAMES, C._theta(q), C.LB, C.UB) if n in fit.result["names"]
                             and (v <= lo + 1e-6 or v >= hi - 1e-6)],
                "held_out_beside": {k: ev.get(k) for k in ("rms_log_reading_within_press", "level_mean_log_vs_fit", "level_in_band90")}}
            print(name, side, json.dumps(out["splits"][name][side], default=float), flush=True)
    a.out.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()

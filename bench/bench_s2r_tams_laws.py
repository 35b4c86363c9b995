"""The TAMS chain fit, leave one cover out, under each creep law (session 20, issue 15; a diagnostic, nothing adopted).

    python bench/bench_s2r_tams_laws.py TAMS.h5 [-o bench/results/s2r-tams-laws.json]

TAMS.h5: the TAMS calibration presses imported as `piezotwin sim2real divider` reads them (`piezotwin import`, see
docs). For each cover (thicksil, thinsil, nosil) held out, `sensors.chain_fit.fit_chain` on the other two covers'
runs, as step 1 of `piezotwin sim2real divider` fits them (its prior, 20 Hz, 16 bootstrap fits), with
creep_law "force" (the default) and "aging"; then `evaluate` on the held-out cover. Per fit: the within-press rms
ln-reading error on the fit runs and held out (issue 15's target: <= 0.3 held out), the held-out levels inside the
90 % band, the plateau ratio real vs simulated, the fitted shape and which shape parameters sit on a bound of the
fit (sensors.chain_fit LB / UB).

What it showed (bench/results/s2r-tams-laws.json):
- five of the six fits end with shape parameters on bounds (exponent 4.0, creep amplitude 50, time constants
  0.02 / 1000 s), so the TAMS presses do not pin the chain's shape;
- the aging law fits the training covers better at every split (0.16-0.17 against 0.20-0.22), and held out it
  gives 0.265 / 0.212 / 0.187 (thicksil / thinsil / nosil) against 0.319 / 0.181 / 0.264;
- but its amplitude sits on the bound, so it works as another static law, not as contact aging.
No rule was written before these were seen, so nothing is adopted from them."""

from __future__ import annotations

import argparse
import fnmatch
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from learn.sim2real import S2R_BUDGET, _chain_prior
from sensors import chain_fit as C

COVERS = ("thicksil", "thinsil", "nosil")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("recording", type=Path)
    ap.add_argument("-o", "--out", type=Path, default=Path(__file__).parent / "results" / "s2r-tams-laws.json")
    a = ap.parse_args()
    runs = C.load_real_runs(a.recording, input_channel="sensor", target="force", rate_hz=float(S2R_BUDGET["fit_rate_hz"]))
    res: dict = {"recording": str(a.recording), "n_boot": int(S2R_BUDGET["n_boot"]), "laws": {}}
    for law in ("force", "aging"):
        res["laws"][law] = {}
        for cover in COVERS:
            glob = f"*-{cover}-*"
            train = [r for r in runs if not fnmatch.fnmatch(r.key, glob)]
            test = [r for r in runs if fnmatch.fnmatch(r.key, glob)]
            p0 = replace(_chain_prior("divider", runs), creep_law=law)
            fit = C.fit_chain(train, p0, n_boot=int(S2R_BUDGET["n_boot"]), seed=0)
            held = C.evaluate(fit, test)
            th = C._theta(fit.params)
            free = C._free(True)
            on_bound = [C.NAMES[i] for i in free if np.isclose(th[i], C.LB[i], rtol=1e-3, atol=1e-3)
                        or np.isclose(th[i], C.UB[i], rtol=1e-3, atol=1e-3)]
            pd = held.get("plateau_drop", {})
            row = {"held_out_runs": [r.key for r in test],
                   "within_press_fit_runs": fit.error["rms_log_reading_within_press"],
                   "within_press_held_out": held["rms_log_reading_within_press"],
                   "held_out_levels_in_band90": held["level_in_band90"],
                   "plateau_real_median": pd.get("real_median"), "plateau_sim_median": pd.get("sim_median"),
                   "exponent": fit.params.exponent, "creep_amplitude": fit.params.creep_amplitude,
                   "creep_force_n": fit.params.creep_force_n, "tau_min_s": fit.params.tau_min_s,
                   "tau_max_s": fit.params.tau_max_s, "on_bound": on_bound}
            res["laws"][law][cover] = row
            print(f"{law:6s} {cover:8s} within-press fit {row['within_press_fit_runs']:.3f} held-out "
                  f"{row['within_press_held_out']:.3f}, band {row['held_out_levels_in_band90']:.2f}, on bounds: "
                  f"{', '.join(on_bound) or '-'}", flush=True)
    a.out.write_text(json.dumps(res, indent=1))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

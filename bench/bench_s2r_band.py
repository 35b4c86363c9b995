"""Why held-out press levels miss the fitted 90 % band of a new run (ninth round of issue 15).

    python bench/bench_s2r_band.py NAME=RUN [NAME=RUN ...] -o bench/results/s2r-band.json

Each RUN is a finished `sim2real` folder (fit.json, metrics.json; its recording and test runs as recorded). Per
split, on the held-out runs (the same profiled press levels as sensors.chain_fit.evaluate: ln level relative to the
fitted ln r0, each press's level fitted at the chain's shape) against the band half width h = 1.645 sd_band
(new_run_band90: sd_band^2 = sd_w^2 + sd_run^2 + se^2):
  center: the held-out levels' mean offset from the band's center, in ln and in sd_band (a shifted center);
  spread: the held-out levels' sd about their own mean against sd_band (a band too narrow or too wide), and split
  like the fit, within-run sd and the std of the held-out run means;
  inside: the share inside the band as fitted, inside the band moved onto the held-out mean (the spread alone), and
  inside a band of the fitted center with the held-out sd (the center alone);
  the training side: the fit's within-run sd, run-level sd (ANOVA and with the prior) and its runs.
Nothing here changes the band: it names where each miss sits (CHANGELOG, ninth round).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import numpy as np


def held_levels(run: Path) -> dict:
    from sensors import chain_fit as C

    fj = json.loads((run / "fit.json").read_text())
    m = json.loads((run / "metrics.json").read_text())
    p = C.ChainParams.from_json(fj["params"])
    runs = C.load_real_runs(fj["recording"], rate_hz=float(m["budget"]["fit_rate_hz"]))
    test = [r for r in runs if r.key not in fj["fit_runs"]]
    data = C._Data(test, p, 0.1, 0.05)
    idx = np.arange(len(data.presses))
    _, lev = C._profile(data, p, idx)
    rel = lev - np.log(p.r0_ohm)
    run_of = np.array([data.presses[j].run for j in idx])
    h = float(fj["level_band90_log"][1])
    sd_band = h / 1.645
    off = float(np.mean(rel))
    sd = float(np.std(rel, ddof=1)) if len(rel) > 1 else 0.0
    means = np.array([rel[run_of == r].mean() for r in np.unique(run_of)])
    within = np.concatenate([rel[run_of == r] - rel[run_of == r].mean() for r in np.unique(run_of)])
    dof = max(len(rel) - len(means), 1)
    err = fj["error"]["level_run_sd"]
    return {
        "recording": fj["recording"], "fit_runs": fj["fit_runs"], "held_out_runs": [r.key for r in test],
        "n_presses": len(rel), "band_half_width_log": h, "band_sd_log": sd_band,
        "center_offset_log": off, "center_offset_in_band_sd": off / sd_band,
        "held_out_sd_log": sd, "held_out_sd_over_band_sd": sd / sd_band,
        "held_out_within_run_sd_log": float(np.sqrt(np.sum(within ** 2) / dof)) if len(rel) > len(means) else None,
        "held_out_run_means_log": means.tolist(),
        "inside_as_fitted": float(np.mean(np.abs(rel) <= h)),
        "inside_band_on_held_out_mean": float(np.mean(np.abs(rel - off) <= h)),
        "inside_fitted_center_held_out_sd": float(np.mean(np.abs(rel) <= 1.645 * sd)) if sd > 0 else None,
        "fit": {"within_run_sd_log": err["within_run_sd"], "run_sd_anova_log": err["anova"], "run_sd_log": err["point"],
                "n_runs": err["n_runs"], "n_presses": fj["error"]["n_presses"],
                "press_level_sd_log": float(np.std(fj["press_levels_log"], ddof=1))},
    }


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", nargs="+", help="NAME=RUN")
    ap.add_argument("-o", "--out", required=True, type=Path)
    a = ap.parse_args(argv)
    out = {"command": "python bench/bench_s2r_band.py " + shlex.join(sys.argv[1:] if argv is None else argv), "splits": {}}
    for s in a.runs:
        name, run = s.split("=", 1)
        d = held_levels(Path(run))
        out["splits"][name] = d
        print(f"{name}: inside {d['inside_as_fitted']:.2f}, offset {d['center_offset_log']:+.2f} ln "
              f"({d['center_offset_in_band_sd']:+.2f} sd_band), sd ratio {d['held_out_sd_over_band_sd']:.2f}, inside on "
              f"own mean {d['inside_band_on_held_out_mean']:.2f}, fitted center + own sd {d['inside_fitted_center_held_out_sd']}",
              flush=True)
    a.out.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()

"""How spread the simulated presses read at equal force beside the real training presses, every developers' split
(session 21, issue 15; a check of the randomization on training data only, nothing adopted).

    python bench/bench_s2r_press_spread.py --tams TAMS.h5 --lupasic LUPASIC.h5 [-o bench/results/s2r-press-spread.json]

Per split: step 1 of `piezotwin sim2real` (the fit with its bootstrap, on the training runs), step 2 (the randomized
generation at the budget's size: 96 episodes, TAMS 32 as the README runs it), then sensors.chain_fit.press_spread:
the robust sd of ln plateau reading about a quadratic in ln plateau force, real training presses against the
simulated presses inside their force range, and the share of outliers (presses that missed the film). The default
randomization and `--run-level` (the hierarchical run-level gain) side by side.

What it showed (bench/results/s2r-press-spread.json; robust sd of ln plateau reading at equal force, real / sim):
- Lupasic: pike1's 14 runs 0.475 / 0.598 (x1.26; x1.16 with --run-level), pike2's 2 runs 0.743 / 0.687 (x0.92).
  The simulated film is about as spread as the real one (decomposed on pike1: the press levels alone give 0.51,
  the creep adds ~0.05, the episode gain ~0.03); 2.5 % of the simulated presses miss the film (miss_prob), none of
  the real plateaus.
- TAMS: every real plateau (~0.9 N) sits on the readout floor (the series resistance: sd 0.001-0.016 ln), the
  simulated ones spread by 0.21-0.25 ln (x15-x140): the leave-one-cover-out fits draw press levels (sd 0.65-2.1 ln)
  and episode gains (sd 0.7-3.4 ln) that hold the two training covers' difference, so some simulated presses stay
  off the floor. The tunneling term (bench_s2r_tunnel.py) does not change it (0.22-0.24).
"""

from __future__ import annotations

import fnmatch
import json
import os
import platform
import tempfile
from pathlib import Path

from bench_s2r_tunnel import real_recordings
from learn.sim2real import S2R_BUDGET, _chain_prior, generate_step, simulated_press_spread
from sensors import chain_fit as C

SPLITS = (("velostat", "lupasic", "*pike2*"), ("velostat", "lupasic", "*pike1*"), ("divider", "tams", "*-thicksil-*"),
          ("divider", "tams", "*-thinsil-*"), ("divider", "tams", "*-nosil-*"))


def main() -> None:
    a, data = real_recordings("s2r-press-spread.json")
    res: dict = {"recordings": {"tams": str(a.tams), "lupasic": str(a.lupasic)}, "splits": []}
    for family, rec, glob in SPLITS:
        runs = data[rec]
        train = [r for r in runs if not fnmatch.fnmatch(r.key, glob)]
        adc = any(r.attrs.get("adc_full_scale") for r in runs)
        fit = C.fit_chain(train, _chain_prior(family, runs), n_boot=int(S2R_BUDGET["n_boot"]), seed=0, level_prior=not adc)
        B = dict(S2R_BUDGET, n_episodes=32 if adc else int(S2R_BUDGET["n_episodes"]))
        row = {"family": family, "held_out": glob, "n_episodes": B["n_episodes"]}
        for name, rl in (("default", False), ("run_level", True)):
            rand = C.randomization_from_fit(fit, train, run_level=rl)
            with tempfile.TemporaryDirectory() as d:
                f = Path(d) / "sim.h5"
                generate_step(fit.params, rand, f, B, 0)
                row[name] = simulated_press_spread(f, train, fit.params)
            sp = row[name]
            print(f"{family:8s} {glob:14s} {name:9s} real {sp.get('real_ln_reading_sd', float('nan')):.3f} sim "
                  f"{sp.get('sim_ln_reading_sd', float('nan')):.3f} x{sp.get('ratio') or float('nan'):.2f} outliers "
                  f"{sp.get('real_outlier_share', float('nan')):.3f} / {sp.get('sim_outlier_share', float('nan')):.3f} "
                  f"({sp.get('n_real')} / {sp.get('n_sim')} presses)", flush=True)
        res["splits"].append(row)
    res["machine"] = {"platform": platform.platform(), "cpus": os.cpu_count(), "note": "the 2-core development machine"}
    a.out.write_text(json.dumps(res, indent=1))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

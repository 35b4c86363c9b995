"""The two-point calibration's run level shrunk by the fitted levels model, scored by the rule written before it ran
(session 26, issue 15; `results/s2r-two-point-shrink-rule.md`).

    python bench/bench_s2r_two_point_shrink.py --run pike1-to-pike2=DIR [--run SPLIT=DIR ...]
                                               [-o bench/results/s2r-two-point-shrink.json]

Each DIR is a `piezotwin sim2real` run folder of that split (its fit.json, its pre-trained checkpoint and its state.json
key: recording, test glob, seed, channels). Only the zero-shot and the zero-shot after the two-point calibration are
scored, with the recorded level ("measured") and the shrunk one (`learn.sim2real.run_level_shrinkage`), through the
loop's own functions (`real_split`, `two_point_zero_shot`); the folder's zero-shot must equal the recorded file's
(`experiments/sim2real-<split>.json`), else the split is flagged. Rule: adopt the shrunk level as the default only if
the mean over the splits of the two-point RMSE (% of the test runs' full scale) falls and no split's rises by more than
10 % (relative).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "bench" / "results"


def _recorded(split: str) -> Path:
    return RESULTS / "experiments" / (f"sim2real-{split}.json" if split.startswith("tams-") else f"sim2real-velostat-{split}.json")


def score(split: str, run_dir: Path) -> dict:
    from learn.checkpoint import load_checkpoint
    from learn.sim2real import real_split, run_level_shrinkage, score_on, two_point_zero_shot
    from sensors import chain_fit as C

    key = json.loads((run_dir / "state.json").read_text())["key"]
    p, fj = C.load_params(run_dir / "fit.json")
    rate = float(key["budget"]["fit_rate_hz"])
    inp, tgt = key.get("channels", ["sensor", "force"])
    sp = real_split(p, key["recording"], key["test"], int(key["seed"]), inp, tgt, rate)
    base = load_checkpoint(run_dir / "checkpoints" / "pretrained")
    full = max(float(max(s.y.max() for s in sp.test)), 1e-9)
    zs = score_on(base, sp.test)["rmse"]
    rec = json.loads(_recorded(split).read_text())["results"]["zero_shot"]
    out = {"split": split, "run": str(run_dir), "full_scale_n": full, "zero_shot_rmse": zs,
           "zero_shot_rmse_recorded": rec["rmse"], "zero_shot_as_recorded": abs(zs - rec["rmse"]) <= 1e-6 * max(1.0, zs),
           "shrinkage_k": run_level_shrinkage(p, fj)}
    for how in ("measured", "shrunk"):
        t = two_point_zero_shot(base, p, sp.test, rate, how, fj)
        out[how] = {"rmse": t["rmse"], "rmse_pct_full_scale": 100 * t["rmse"] / full, "mae": t["mae"], "r2": t["r2"],
                    "level_ln": t["level_ln"], "level_ln_measured": t["level_ln_measured"]}
    out["two_point_recorded_rmse"] = rec["two_point_gain"]["rmse"]
    out["rel_change"] = out["shrunk"]["rmse"] / out["measured"]["rmse"] - 1
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="append", required=True, help="SPLIT=DIR")
    ap.add_argument("-o", "--out", type=Path, default=RESULTS / "s2r-two-point-shrink.json")
    a = ap.parse_args()
    rows = [score(*r.split("=", 1)[0:1], Path(r.split("=", 1)[1])) for r in a.run]
    pct = {h: sum(r[h]["rmse_pct_full_scale"] for r in rows) / len(rows) for h in ("measured", "shrunk")}
    checks = {"mean_pct_falls": pct["shrunk"] < pct["measured"],
              "no_split_rises_10pct": max(r["rel_change"] for r in rows) <= 0.10}
    res = {"rule": "results/s2r-two-point-shrink-rule.md", "splits": rows, "mean_pct_full_scale": pct, "checks": checks,
           "adopted": all(checks.values()) and len(rows) == 5, "n_splits": len(rows)}
    a.out.write_text(json.dumps(res, indent=1) + "\n")
    for r in rows:
        print(f"{r['split']:24s} k {r['shrinkage_k']:.3f}  zero-shot {r['zero_shot_rmse']:.4g} (as recorded: "
              f"{r['zero_shot_as_recorded']})  two-point measured {r['measured']['rmse_pct_full_scale']:.1f} % -> shrunk "
              f"{r['shrunk']['rmse_pct_full_scale']:.1f} % ({100 * r['rel_change']:+.1f} %)")
    print(f"mean {pct['measured']:.2f} -> {pct['shrunk']:.2f} % FS; checks {checks}; adopted {res['adopted']}; wrote {a.out}")


if __name__ == "__main__":
    main()

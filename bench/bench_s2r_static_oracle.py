"""How far each sim2real split's test runs can be read by a static calibration curve at all (issue 15's pooled
target: fine-tuned <= 12 % of full scale).

    python bench/bench_s2r_static_oracle.py [--lupasic /tmp/s2r/lupasic.h5] [--tams /tmp/s2r/tams.h5]

For each recorded split (bench/results/experiments/sim2real-*.json) the test runs are loaded as step 4 of
`piezotwin sim2real` loads them (the recorded input map: ln(reading) at 20 Hz) and two static curves
(learn.sim2real.StaticCurve: force as a monotone function of ln reading) are scored on them:
- the recorded baseline, fitted on the split's training runs (must give the recorded static_curve RMSE: a check
  that the runs were read the same way);
- an oracle, fitted on the test runs themselves (in-sample; learn.sim2real.static_oracle, which `sim2real` now reports
  as `static_oracle` in metrics.json for runs made from now on): no memoryless map of the reading does better on them,
  so its RMSE is what the press-to-press level spread at equal reading leaves to any static reading. A net with
  history can go below it; a target near it asks for that.
Writes bench/results/s2r-static-oracle.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    import sys

    sys.path.insert(0, str(ROOT))
    from learn import finetune as FT
    from learn import metrics as M
    from learn.sim2real import StaticCurve, static_oracle

    ap = argparse.ArgumentParser()
    ap.add_argument("--lupasic", type=Path, default=Path("/tmp/s2r/lupasic.h5"))
    ap.add_argument("--tams", type=Path, default=Path("/tmp/s2r/tams.h5"))
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "s2r-static-oracle.json")
    a = ap.parse_args()
    res = {"input_map": "ln(reading) at 20 Hz (as recorded)", "splits": {}}
    for f in sorted((ROOT / "bench" / "results" / "experiments").glob("sim2real-*.json")):
        m = json.loads(f.read_text())
        rec = a.tams if "tams" in f.stem else a.lupasic
        seqs = {s.key: s for s in FT.apply_map(FT.load_recording(rec, ["sensor"], ["force"], rate_hz=20.0), "log")}
        test = [seqs[k] for k in m["split"]["test"]]
        train = [seqs[k] for k in m["split"]["train"]]
        full = float(m["full_scale_n"])

        def rmse(curve) -> float:
            y = np.concatenate([s.y[:, 0] for s in test])
            return M.rmse(y, np.concatenate([curve.predict(s.x)[:, 0] for s in test]))
        base, oracle = rmse(StaticCurve(train)), static_oracle(test)["rmse"]
        r = m["results"]
        row = {"full_scale_n": full, "static_train_rmse_n": base, "static_train_recorded_n": r["static_curve"]["rmse"],
               "oracle_in_sample_rmse_n": oracle, "oracle_pct_full_scale": 100 * oracle / full,
               "finetuned_pct": r["finetuned"]["rmse_pct_full_scale"], "scratch_pct": r["scratch"]["rmse_pct_full_scale"],
               "static_pct": r["static_curve"]["rmse_pct_full_scale"], "target_pct": 12.0,
               "target_over_oracle": 12.0 / (100 * oracle / full)}
        res["splits"][f.stem.removeprefix("sim2real-")] = row
        print(f"{f.stem:40s} oracle {oracle:.3f} N ({row['oracle_pct_full_scale']:.1f} % FS); static (train) "
              f"{base:.3f} N (recorded {r['static_curve']['rmse']:.3f}); fine-tuned {row['finetuned_pct']:.1f} %, "
              f"scratch {row['scratch_pct']:.1f} %", flush=True)
    a.out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

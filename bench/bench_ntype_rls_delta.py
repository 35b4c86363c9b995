"""Table 1's spread sweep under RLS's starting matrix P0 = I / delta, which the paper does not give (session 26,
issue 14; a diagnostic, nothing changed).

    python bench/bench_ntype_rls_delta.py [--deltas 1e-3,1e-2,1e-1,1,10] [-o bench/results/ntype-rls-delta.json]

Sect. 3.1 trains the RBF output weights by recursive least squares and names no initialisation. RLS of forgetting
factor 1 from P0 = I / delta ends at the ridge solution (H^T H + delta I)^-1 H^T Y (Haykin, Adaptive Filter Theory,
ch. 10), so delta is a ridge penalty on the output weights: Haykin's rule of thumb takes it small at high SNR and
large at low SNR. The experiment uses 1e-3 (`learn.models.rbf.sweep_predict`, about exact least squares on hidden
outputs in [0, 1]). At a large spread the hidden units grow alike and the weights that tell them apart grow large,
so a larger delta shrinks them and costs the large spreads most: the sweep's optimum can move inside the 1-10 sweep
through the solver alone. Table 1 (`rbf_col`) on the paper's task (quick, seed 0), for each delta, with the default
column reading ("crossed") and sect. 2.3's element ("decoupled", `DECOUPLED_ELEMENT`), each on one dataset (made
once per reading, reused for every delta).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

READINGS = {"crossed (default)": [], "decoupled (sect. 2.3's element)": None}


def main() -> None:
    from learn.experiments import ntype as N
    from learn.models import rbf
    from scenes.ntype_config import DECOUPLED_ELEMENT

    ap = argparse.ArgumentParser()
    ap.add_argument("--deltas", default="1e-3,1e-2,1e-1,1,10")
    ap.add_argument("-o", "--out", type=Path, default=Path(__file__).parent / "results" / "ntype-rls-delta.json")
    a = ap.parse_args()
    deltas = [float(x) for x in a.deltas.split(",")]
    default = rbf.sweep_predict.__kwdefaults__["delta"]
    res = {"task": "paper", "mode": "quick", "seed": 0, "model": "rbf_col (Table 1)", "experiment_delta": default,
           "paper_table1_best_spread": 7, "readings": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, over) in enumerate(READINGS.items()):
            over = list(DECOUPLED_ELEMENT) if over is None else over
            data = Path(tmp) / f"data{i}"
            rows = {}
            for d in deltas:
                rbf.sweep_predict.__kwdefaults__["delta"] = d
                t0 = time.perf_counter()
                try:
                    where = Path(tmp) / f"{i}-{d:g}"
                    m = N._task("quick", ["rbf_col"], over, 0, "paper", where, data, False, lambda s: None)
                finally:
                    rbf.sweep_predict.__kwdefaults__["delta"] = default
                f = m["findings"]
                e = f["table1_mean_error_by_spread"]
                rows[f"{d:g}"] = {"best_spread": f["table1_best_spread"], "interior_optimum": f["table1_interior_optimum"],
                                  "best_spread_by_component": f["table1_best_spread_by_component"],
                                  "mean_error_by_spread_pct": e, "seconds": time.perf_counter() - t0}
                print(f"{name}, delta {d:g}: best spread {f['table1_best_spread']} "
                      f"{f['table1_best_spread_by_component']}, mean E at 1 / 4 / 7 / 10: "
                      f"{e['1.0']:.2f} / {e['4.0']:.2f} / {e['7.0']:.2f} / {e['10.0']:.2f} %", flush=True)
            res["readings"][name] = {"overrides": over, "deltas": rows}
    a.out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

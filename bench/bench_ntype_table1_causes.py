"""What keeps ntype's Table 1 (no window) flat in the spread (session 20, issue 14; a diagnostic, nothing changed).

    python bench/bench_ntype_table1_causes.py [-o bench/results/ntype-table1-causes.json]

Table 1's network ("rbf_col", learn/experiments/ntype.py) estimates each force component from the 36 resistances
of its own column type only (paper sect. 3.2). On the paper's task (PAPER_PROTOCOL, quick mode, seed 0, Table 1
alone) it is run with the preset and with the element's couplings to its neighbours cut one at a time: the cover's
depth (the Boussinesq spread of a load onto the neighbours' electrodes) 5 and 2.5 mm instead of 10, and the ideal
readout instead of the scanned matrix (no sneak paths). Beside them, the element's own strain per newton of each
force component for each column (`ntype_params`: the column directions and the element's compliance).

What it showed (bench/results/ntype-table1-causes.json): none of the neighbour couplings moves Table 1. Its error
(~15 % mean, F_x / F_y MAE ~0.39 N against F_z ~0.09 N) and its flat curve come from the element itself. An
inclined column strains under F_z at 1/3 of its strain under its own shear component, and the paper's task draws the three
components independently, so the column's resistance alone cannot separate them and smoothing never hurts. The
paper's resistance ranges (inclined 50 -> 32, normal 25 -> 16 kOhm over 0-4.8 N, one piezo coefficient) fix that
ratio: a stiffer filler in compression (e.g. a bonded layer's shape factor) that decoupled R_x from F_z would
need a piezo coefficient ~6x larger for R_z than for R_x."""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

VARIANTS = {"preset (cover depth 10 mm, feedback scan)": [], "cover depth 5 mm": ["sensor.layer.depth_m=0.005"],
            "cover depth 2.5 mm": ["sensor.layer.depth_m=0.0025"], "ideal readout (no scan matrix)": ["sensor.readout.scan=ideal"]}


def strain_per_newton() -> dict:
    from scenes import load_scene
    from scenes.ntype_config import PAPER_PROTOCOL
    from sensors.ntype.model import ntype_params

    p = ntype_params(load_scene("ntype", PAPER_PROTOCOL))
    s = np.array([[p.normals[j] @ (p.compliance @ np.eye(3)[k]) / p.lengths_m[j] for k in range(3)] for j in range(3)])
    return {"rows": ["R_x", "R_y", "R_z"], "cols": ["F_x", "F_y", "F_z"], "strain_per_n": s.tolist(),
            "R_x_Fz_over_Fx": float(abs(s[0, 2] / s[0, 0])), "R_z_Fy_over_Fz": float(abs(s[2, 1] / s[2, 2]))}


def main() -> None:
    from learn.experiments import ntype as N

    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", type=Path, default=Path(__file__).parent / "results" / "ntype-table1-causes.json")
    a = ap.parse_args()
    res = {"task": "paper", "mode": "quick", "seed": 0, "model": "rbf_col (Table 1)", "element": strain_per_newton(),
           "variants": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, over) in enumerate(VARIANTS.items()):
            t0 = time.perf_counter()
            where = Path(tmp) / str(i)
            m = N._task("quick", ["rbf_col"], over, 0, "paper", where, where / "data", False, lambda s: None)
            f = m["findings"]
            res["variants"][name] = {"overrides": over, "best_spread": f["table1_best_spread"],
                                     "interior_optimum": f["table1_interior_optimum"],
                                     "mean_error_by_spread_pct": f["table1_mean_error_by_spread"],
                                     "mae_n_at_spread7": f["table1_mae_n_at_spread7"], "seconds": time.perf_counter() - t0}
            e = f["table1_mean_error_by_spread"]
            print(f"{name}: best spread {f['table1_best_spread']}, mean E at 7 {e['7.0']:.2f} %, at 10 {e['10.0']:.2f} %, "
                  f"MAE at 7 {f['table1_mae_n_at_spread7']}", flush=True)
    a.out.write_text(json.dumps(res, indent=1))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

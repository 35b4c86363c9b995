"""Why Table 1's spread optimum runs to the sweep's edge and why F_z gains little from the sliding window (issue 14,
ntype part, session 10): the paper's inputs (eq. 13: each column type's resistances min-max scaled onto its kOhm
range, R_x, R_y -> [32, 50], R_z -> [16, 25], ntype sect. 3.2) as our experiment builds them, and affine least-squares
maps on the same inputs, folds and metric (eq. 14 over |F| >= 0.5 N, learn/experiments/ntype.py), no RBF:

  t1_linear                  Table 1's inputs and outputs (36 resistances of column c -> the 36 F_c), affine
  own_column_per_element     element m's F_c from its own column c alone (one affine map per element)
  all_columns_linear         all 108 resistances -> the 36 F_c
  w{1,5,7}_linear_shared     the sliding-window inputs (learn.experiments.ntype.window_inputs) -> (F_x, F_y, F_z),
                             one affine map shared by the 36 elements, as the window RBF is
  fz_from_window5_rz         F_z of element m from the R_z of its window-5 elements (per element)
  fz_from_wires_rz           F_z of element m from the R_z of the elements sharing its upper or lower wire (its
                             row and column of the array, the scanned readout's crosstalk paths; per element)

Least squares: Gauss, normal equations with a 1e-6 ridge. Writes bench/results/ntype-linear-<mode>[-seedN].json.

  python bench/bench_ntype_linear.py --mode quick --seed 0 --data runs/ntype-linear
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def affine(A: np.ndarray, B: np.ndarray, lam: float = 1e-6):
    A1 = np.c_[A, np.ones(len(A))]
    W = np.linalg.solve(A1.T @ A1 + lam * np.eye(A1.shape[1]), A1.T @ B)
    return lambda Z: np.c_[Z, np.ones(len(Z))] @ W


def maps(Ntr, Ytr, Nte, pad):
    from learn.experiments import ntype as NT

    iy, ix = np.divmod(np.arange(36), 6)
    P: dict[str, np.ndarray] = {}
    p = np.zeros(Nte.shape)
    for c in range(3):
        p[..., c] = affine(Ntr[..., c], Ytr[..., c])(Nte[..., c])
    P["t1_linear"] = p
    p = np.zeros(Nte.shape)
    for c in range(3):
        for m in range(36):
            p[:, m, c] = affine(Ntr[:, m, c : c + 1], Ytr[:, m, c])(Nte[:, m, c : c + 1])
    P["own_column_per_element"] = p
    A, At = Ntr.reshape(len(Ntr), -1), Nte.reshape(len(Nte), -1)
    P["all_columns_linear"] = np.stack([affine(A, Ytr[..., c])(At) for c in range(3)], -1)
    for w in (1, 5, 7):
        f = affine(NT.window_inputs(Ntr, w, pad), Ytr.reshape(-1, 3))
        P[f"w{w}_linear_shared"] = f(NT.window_inputs(Nte, w, pad)).reshape(Nte.shape)
    for name, near in (("fz_from_window5_rz", lambda m: (abs(iy - iy[m]) + abs(ix - ix[m])) <= 1),
                       ("fz_from_wires_rz", lambda m: (iy == iy[m]) | (ix == ix[m]))):
        p = np.full(Nte.shape, np.nan)
        for m in range(36):
            nb = np.flatnonzero(near(m))
            p[:, m, 2] = affine(Ntr[:, nb, 2], Ytr[:, m, 2])(Nte[:, nb, 2])
        P[name] = p
    return P


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", default="quick")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", type=Path, default=Path("runs/ntype-linear"))
    ap.add_argument("--out", type=Path, default=Path("bench/results"))
    a = ap.parse_args()
    from learn.data import dataset_fingerprint, dumps, load_sequences
    from learn.experiments import ntype as NT
    from learn.experiments.common import make_data

    md = NT.MODES[a.mode]
    data = make_data(a.data / f"{a.mode}-s{a.seed}" / "paper", NT.scene(md, [], a.seed, "paper"), print)
    seqs = load_sequences(data, NT.INPUTS, NT.TARGETS)
    X = [s.x.reshape(len(s), 36, 3) for s in seqs]
    Y = [s.y.reshape(len(s), 36, 3) for s in seqs]
    rest, _ = NT.sensor_law(data)
    folds = NT.kfold_episodes(len(seqs), md.folds, a.seed)
    t0 = time.process_time()
    errs: dict[str, list] = {}
    for te in folds:
        tr = np.setdiff1d(np.arange(len(seqs)), te)
        Xtr, Ytr = np.concatenate([X[i] for i in tr]), np.concatenate([Y[i] for i in tr])
        Xte, Yte = np.concatenate([X[i] for i in te]), np.concatenate([Y[i] for i in te])
        lo, hi = NT.minmax_fit(Xtr)
        Ntr, Nte = NT.to_paper_scale(Xtr, lo, hi), NT.to_paper_scale(Xte, lo, hi)
        for k, p in maps(Ntr, Ytr, Nte, NT.to_paper_scale(rest, lo, hi)).items():
            e = NT.component_errors(Yte, np.nan_to_num(p), md.min_abs_ref)
            errs.setdefault(k, []).append({c: (e[f"E_{c}"] if not np.isnan(p[..., i]).any() else None)
                                           for i, c in enumerate(NT.COMPONENTS)})
    Xall, Yall = np.concatenate(X), np.concatenate(Y)
    lo, hi = NT.minmax_fit(Xall)
    Nall = NT.to_paper_scale(Xall, lo, hi)
    cols = ("R_x", "R_y", "R_z")
    inputs = {c: {"raw_min_kohm": float(lo[i] / 1e3), "raw_max_kohm": float(hi[i] / 1e3),
                  "paper_range_kohm": list(NT.RANGES[i]),
                  "scaled_p1_p50_p99": [float(v) for v in np.percentile(Nall[..., i], [1, 50, 99])],
                  "corr_with_Fx_Fy_Fz": [float(np.corrcoef(Xall[..., i].ravel(), Yall[..., k].ravel())[0, 1]) for k in range(3)]}
              for i, c in enumerate(cols)}
    res = {"experiment": "ntype", "bench": "linear maps on the paper's inputs", "mode": a.mode, "seed": a.seed,
           "samples": len(Xall), "folds": md.folds, "min_abs_ref_n": md.min_abs_ref,
           "dataset": dataset_fingerprint(data), "inputs": inputs,
           "linear_E_percent": {k: {c: (float(np.mean([f[c] for f in v])) if v[0][c] is not None else None)
                                    for c in NT.COMPONENTS} for k, v in errs.items()},
           "cpu_s": round(time.process_time() - t0, 1)}
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"ntype-linear-{a.mode}{'' if a.seed == 0 else f'-seed{a.seed}'}.json"
    path.write_text(dumps(res))
    for k, v in res["linear_E_percent"].items():
        print(f"{k:28s}", " / ".join("-" if x is None else f"{x:.2f}" for x in v.values()))
    print("wrote", path)


if __name__ == "__main__":
    main()

"""fabric experiment (paper 000, Abdul-Hussain et al.): BP network trained by Levenberg-Marquardt on the
1/3/6/12-layer fabric sensors, max hysteresis error before/after and Appendix Table 2 beside the paper's.

  data     simulate.generation.run.generate on fabric_1/3/6/12: force-controlled staircases (0.1 N steps, 2 s dwell, a
           full-range cycle then random minor loops, the paper's protocol). Training episodes from root seed
           ``seed``; the test episodes are a second dataset from root seed ``seed + 1000``: new random force
           sequences, never seen in training (the paper's Fig. 13 validation). One observation per force
           level: the multimeter reading at the end of its dwell (as the paper reads it), with the applied
           force at that instant and the nominal level (for the loading/unloading branches).
  target   the paper's R_estimated: a polynomial R(F) fitted by least squares to the training readings of both
           branches (cubic for 1 layer, eq. 6; quartic for 3, 6, 12 layers, eqs. 7-9), evaluated at the
           applied force. Our coefficients are printed beside the paper's.
  models   bp_lm (the paper's: (R_t, R_{t-1}) -> 5 -> 5 sigmoid -> R, Levenberg-Marquardt, learn.models.bpnet);
           mean (trivial), linear and cubic (static R_t -> target, learn.models.classical estimators);
           tcn (ours): a seed ensemble (learn.models.ensemble) of ``tcn_members`` causal TCNs (learn.models.tcn)
           over the history of readings (R, ln R) and a Prandtl-Ishlinskii play-operator bank on ln R (Kuhnen
           2003), training seeds seed..seed+n-1, estimate = their mean; the
           member count is fixed per mode before any test, and each member's test and validation scores are
           reported (nothing is selected on the test episodes).
  metrics  max hysteresis error % FSO: per loop (rise from a valley to a peak and fall to the next valley),
           max |y_up - y_down| at equal nominal force over the output span of the episode's full-range cycle;
           reported for the full-range cycle (the paper's 24.2 -> 13.5 % figure, 1 layer) and as the worst
           loop. MSE (kOhm^2, the paper's unit read as kOhm) and R (Pearson) of the output against the target.
  table 2  bp_lm trained on n random observations (6, 11, 14, 18, 21, 29, 46; the paper's column), MSE and R
           on those observations and on the test episodes, per layer count.
  report   report.md, metrics.json, loops.png, hysteresis.png, table2.png, lm_training.png, checkpoints/.

Modes: "full" = the presets' episode counts, the paper's 0.1 N steps for every sensor; "quick" = 7 training and 3
test episodes per sensor, 0.1 N steps for 1 layer and 0.2 / 0.4 / 0.5 N for 3 / 6 / 12 layers (about 40 levels
up the full range, as for 1 layer; a few minutes on 2 cores); "tiny" = 1 and 3 layers, seconds, for tests only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from learn import metrics as M
from learn.data import Sequence, dataset_fingerprint, dumps, load_sequences
from learn.experiments.common import fit_model, fmt, md_table, select_mode

KEY = "fabric"
LAYERS = (1, 3, 6, 12)
PRESET = {n: f"fabric_{n}" for n in LAYERS}
POLY_DEGREE = {1: 3, 3: 4, 6: 4, 12: 4}  # eqs. 6-9
KOHM = 1e3
ORDER = ["linear", "cubic", "bp_lm", "tcn"]
LABELS = {"raw": "Uncompensated reading", "mean": "Mean (trivial)", "linear": "Linear R_t", "cubic": "Cubic R_t",
          "bp_lm": "BP net, LM (paper's model)", "tcn": "TCN + play bank, seed ensemble (ours)"}

PAPER_HYST = {1: (24.2, 13.5)}  # % FSO before / after the BP network (abstract, sect. 3.3)
PAPER_OBS = [6, 11, 14, 18, 21, 29, 46]
PAPER_TABLE2 = {  # Appendix 1, Table 2: layers -> observations -> (MSE, R)
    1: {6: (9.41e-05, 0.996), 11: (0.0039, 0.9975), 14: (0.0515, 0.9992), 18: (0.0263, 0.9988),
        21: (0.0058, 0.9997), 29: (9.9327e-05, 0.999), 46: (0.0261, 0.9972)},
    3: {6: (6.7356e-05, 0.999), 11: (0.0045, 0.9983), 14: (0.0515, 0.9992), 18: (0.1109, 0.9997),
        21: (0.0028, 1.0), 29: (0.1510, 0.9973), 46: (0.0114, 0.9984)},
    6: {6: (0.0001, 1.0), 11: (0.0055, 0.9997), 14: (0.0107, 0.9998), 18: (0.1736, 0.9995),
        21: (0.0051, 1.0), 29: (0.0051, 1.0), 46: (0.0042, 0.9994)},
    12: {6: (0.0034, 0.9992), 11: (0.0222, 0.9985), 14: (0.0842, 0.9989), 18: (0.9985, 0.9993),
         21: (0.2538, 0.9965), 29: (0.9731, 0.9728), 46: (0.2597, 0.9964)},
}
PAPER_TABLE1_R = {"training": 0.999967, "validation": 0.99992, "test": 0.999977, "overall": 0.99973}


@dataclass
class Mode:
    name: str
    layers: tuple[int, ...]
    train_episodes: dict[int, int]
    test_episodes: int
    scene: list[str]
    per_layer: dict[int, list[str]] = field(default_factory=dict)
    models: dict[str, dict[str, Any]] = field(default_factory=dict)
    observations: list[int] = field(default_factory=lambda: list(PAPER_OBS))
    obs_repeats: int = 3
    latency_samples: int = 200
    tcn_members: int = 5  # ours is a seed ensemble of this many TCNs (learn.models.ensemble), fixed before any test


def _modes() -> dict[str, Mode]:
    bp = {"restarts": 3}
    # ours: ln R joins R as an input (the contact law's scale), 32 channels, 127 readings of history; chosen by
    # cross-validation over the training episodes (never the test episodes; see README, learn: fabric)
    # plus (issue 13) a Prandtl-Ishlinskii play bank on ln R (learn.models.tcn, Kuhnen 2003): the turning-point memory
    # the sensor's own play bank and knit set keep. Widths 2-50 % of the training ln R span  # estimate: they bracket
    # the presets' play thresholds (1-25 % of the force range; ln R is steeper at low force) and the protocol's minor loops;
    # fixed before any test, the same for every layer count and mode
    tcn = {"channels": 32, "dilations": [1, 2, 4, 8, 16, 32], "chunk": 48, "batch_size": 16, "lr": 3e-3,
           "max_epochs": 200, "patience": 25, "log_inputs": [0], "play_widths": [0.02, 0.05, 0.1, 0.2, 0.35, 0.5]}
    # 16 training episodes for every layer count (issue 13: 12 layers had 8, half the presses the others learn from)
    full = Mode("full", LAYERS, {n: 16 for n in LAYERS}, 4, ["generation.threads=1"],
                models={"mean": {}, "linear": {}, "cubic": {}, "bp_lm": {"restarts": 5}, "tcn": tcn}, obs_repeats=5)
    # quick: the full-range cycle keeps ~40 levels up for every sensor (1 layer: the paper's 0.1 N steps)
    coarse = {3: ["protocol.stair_step_n=0.2"], 6: ["protocol.stair_step_n=0.4"], 12: ["protocol.stair_step_n=0.5"]}
    quick = Mode("quick", LAYERS, {n: 7 for n in LAYERS}, 3, ["generation.threads=1"], per_layer=coarse,
                 models={"mean": {}, "linear": {}, "cubic": {}, "bp_lm": bp,
                         "tcn": {**tcn, "max_epochs": 100, "patience": 20}})
    tiny = Mode("tiny", (1, 3), {1: 5, 3: 5}, 2,
                ["generation.threads=1", "protocol.stair_cycles_min=3", "protocol.stair_cycles_max=4"],
                per_layer={3: ["protocol.stair_step_n=0.4"]},
                models={"mean": {}, "linear": {}, "cubic": {}, "bp_lm": {"restarts": 2, "max_epochs": 300},
                        "tcn": {**tcn, "channels": 8, "dilations": [1, 2, 4], "max_epochs": 30, "patience": 10}},
                observations=[6, 21, 46], obs_repeats=1, latency_samples=40, tcn_members=2)
    return {m.name: m for m in (full, quick, tiny)}


MODES = _modes()


# ------------------------------------------------------------------------------------------------ data

def scenes_for(mode: Mode, n: int, overrides: list[str], seed: int):
    """(train, test) scene configs of one layer count (raises scenes.ConfigError, a ValueError, on a bad override)."""
    from scenes import load_scene

    base = [*mode.scene, *mode.per_layer.get(n, []), *overrides]
    ne = mode.train_episodes[n]
    tr = load_scene(PRESET[n], [*base, f"generation.episodes={ne}", f"generation.episodes_per_shard={ne}",
                                f"generation.root_seed={seed}"])
    te = load_scene(PRESET[n], [*base, f"generation.episodes={mode.test_episodes}",
                                f"generation.episodes_per_shard={mode.test_episodes}", f"generation.root_seed={seed + 1000}"])
    return tr, te


def readings(seqs: list[Sequence], cfg) -> list[Sequence]:
    """Episode time series -> one observation per force level: the reading at the end of its dwell (sample
    ceil((settle + (j+1) dwell) fs) - 1, as simulate.characterize.fabric reads it). x = resistance_measured,
    y = applied force (replaced by the target later); extra: level (nominal N), force (N), r_true (ohm).
    The rest after the last level (episodes are padded to the longest plan) is dropped."""
    p, fs = cfg.protocol, cfg.sampling.sample_rate_hz
    out = []
    for s in seqs:
        T = len(s)
        j = np.arange(int((T / fs - p.settle_s) / p.stair_dwell_s) + 1)
        k = np.ceil((p.settle_s + (j + 1) * p.stair_dwell_s) * fs - 1e-6).astype(int) - 1
        k = k[k < T]
        level = np.round(np.asarray(s.extra["target"], float)[k], 6)
        nz = np.flatnonzero(level > 0)
        keep = (nz[-1] + 2) if len(nz) else 1
        k, level = k[:keep], level[:keep]
        force = np.asarray(s.extra["force"], float)[k]
        ex = {"level": level, "force": force, "r_true": np.asarray(s.extra["resistance"], float).reshape(T, -1)[k, 0]}
        out.append(Sequence(s.x[k], force[:, None], s.inputs, ["r_static"], {**s.units, "r_static": "ohm"},
                            dict(s.meta), ex))
    return out


def make_data(root: Path, n: int, cfgs, log: Callable[[str], None]) -> tuple[list[Sequence], list[Sequence], dict]:
    from sensors.warp_setup import init_warp
    from simulate.generation.run import generate

    init_warp()
    parts, fps = [], {}
    for name, cfg in zip(("train", "test"), cfgs):
        d = root / PRESET[n] / name
        t0 = time.perf_counter()
        generate(cfg, d)
        seqs = load_sequences(d, ["resistance_measured"], ["force"], extra=["target", "force", "resistance"])
        seqs = readings(seqs, cfg)
        for q in seqs:
            q.meta["key"] = f"{name}/{q.key}"  # the two datasets number their episodes alike
        parts.append(seqs)
        fps[name] = dataset_fingerprint(d)
        log(f"data: {d} ({cfg.generation.episodes} episodes, {sum(len(s) for s in parts[-1])} readings, "
            f"{time.perf_counter() - t0:.1f} s incl. reuse)")
    return parts[0], parts[1], fps


# ------------------------------------------------------------------------------------------------ target

class TargetPolynomial:
    """The paper's R_estimated = a0 + a1 F + ... + an F^n: least squares over the training readings (both
    branches), a classical fit/predict estimator (learn.models.classical.PolynomialRegression on F / F_max)."""

    def __init__(self, degree: int, f_scale: float):
        from learn.models.classical import PolynomialRegression

        self.degree, self.f_scale = int(degree), float(f_scale)
        self.est = PolynomialRegression(self.degree, ridge=0.0)

    def fit(self, F: np.ndarray, R: np.ndarray) -> TargetPolynomial:
        self.est.fit(np.asarray(F, float)[:, None] / self.f_scale, np.asarray(R, float)[:, None])
        return self

    def predict(self, F: np.ndarray) -> np.ndarray:
        return self.est.predict(np.asarray(F, float)[:, None] / self.f_scale)[:, 0]

    def coeffs_kohm(self) -> list[float]:
        """Highest power first (numpy.poly1d order, as PAPER_CURVES), R in kOhm, F in N."""
        c = self.est.coef_[0] / KOHM
        return [float(c[k] / self.f_scale**k) for k in range(self.degree, -1, -1)]


# ------------------------------------------------------------------------------------------------ metrics

def loops(level: np.ndarray) -> list[tuple[int, int, int]]:
    """(start valley, peak, end valley) indices of each loop of a staircase (levels monotone between turns)."""
    lv = np.asarray(level, float)
    d = np.sign(np.diff(lv))
    turns = [0] + [i + 1 for i in range(len(d) - 1) if d[i] != d[i + 1] and d[i] != 0] + [len(lv) - 1]
    out = []
    for a, p, b in zip(turns[:-2], turns[1:-1], turns[2:]):
        if lv[p] > lv[a] and lv[p] > lv[b]:
            out.append((a, p, b))
    return out


def hysteresis(level: np.ndarray, y: np.ndarray) -> dict[str, Any]:
    """Per loop: max |y_up(F) - y_down(F)| at equal nominal force, % of the output span of the episode's first
    (full-range) loop. Returns full_range (the first loop), loops (all), fso (the span), and full_range_paper:
    the first loop's gap over its highest output value (the paper's definition, sect. 3.3)."""
    lp = loops(level)
    if not lp:
        return {"full_range": float("nan"), "loops": [], "fso": float("nan"), "full_range_paper": float("nan")}
    a0, _, b0 = lp[0]
    fso = float(np.ptp(y[a0 : b0 + 1]))
    top = float(np.max(y[a0 : b0 + 1]))
    errs = []
    for a, p, b in lp:
        up = {float(level[i]): float(y[i]) for i in range(a, p + 1)}
        gaps = [abs(up[float(level[i])] - float(y[i])) for i in range(p, b + 1) if float(level[i]) in up]
        errs.append(100.0 * max(gaps) / fso if gaps and fso > 0 else float("nan"))
    paper = errs[0] * fso / top if top > 0 else float("nan")
    return {"full_range": errs[0], "loops": errs, "fso": fso, "full_range_paper": paper}


def score(seqs: list[Sequence], preds: list[np.ndarray]) -> dict[str, Any]:
    """MSE (kOhm^2), R, RMSE/MAE (kOhm), R^2 against the target, and the hysteresis errors."""
    ref = np.concatenate([s.y[:, 0] for s in seqs]) / KOHM
    est = np.concatenate([np.asarray(p).reshape(len(s), -1)[:, 0] for s, p in zip(seqs, preds)]) / KOHM
    out: dict[str, Any] = M.regression_metrics(ref, est)
    out["n_observations"] = len(ref)
    h = [hysteresis(s.extra["level"], np.asarray(p).reshape(len(s), -1)[:, 0]) for s, p in zip(seqs, preds)]
    full = [x["full_range"] for x in h if np.isfinite(x["full_range"])]
    paper = [x["full_range_paper"] for x in h if np.isfinite(x["full_range_paper"])]
    allk = [v for x in h for v in x["loops"] if np.isfinite(v)]
    out.update(hyst_full_mean=float(np.mean(full)) if full else float("nan"),
               hyst_full_worst=float(np.max(full)) if full else float("nan"),
               hyst_loops_max=float(np.max(allk)) if allk else float("nan"),
               hyst_loops_mean=float(np.mean(allk)) if allk else float("nan"), n_loops=len(allk),
               hyst_full_per_episode=full,
               hyst_paper_mean=float(np.mean(paper)) if paper else float("nan"),
               hyst_paper_worst=float(np.max(paper)) if paper else float("nan"))
    return out


# ------------------------------------------------------------------------------------------------ run

def run(
    out_dir: str | Path,
    *,
    mode: str = "quick",
    data_dir: str | Path | None = None,
    overrides: list[str] | None = None,
    models: list[str] | None = None,
    seed: int = 0,
    progress: bool = True,
    log: Callable[[str], None] = print,
    layers: tuple[int, ...] | None = None,
) -> dict[str, Any]:
    """Per layer count: generate (or reuse) train and test data, fit the target polynomial, train every model,
    evaluate on the test episodes, run the Table 2 sweep; write the report. ``layers``: a subset of the mode's
    layer counts (a partial rerun; the API only, the CLI runs them all)."""
    md = select_mode(MODES, mode, models)
    if layers is not None:
        bad = [n for n in layers if n not in md.layers]
        if bad:
            raise ValueError(f"fabric: layers {bad} not in the {md.name} mode's {list(md.layers)}")
        md = replace(md, layers=tuple(int(n) for n in layers))
    cfgs = {n: scenes_for(md, n, list(overrides or []), seed) for n in md.layers}  # validate before writing
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small nets: one thread is fastest, and the machine is shared
    try:
        return _run(md, cfgs, out_dir, data_dir, models, seed, progress, log)
    finally:
        torch.set_num_threads(threads)


def _run(md: Mode, cfgs, out_dir, data_dir, models, seed, progress, log) -> dict[str, Any]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    root = Path(data_dir) if data_dir else out / "data"
    kinds = [k for k in ["mean", *ORDER] if k in md.models and (models is None or k in models or k == "mean")]

    per_layer: dict[str, Any] = {}
    keep: dict[int, Any] = {}
    for n in md.layers:
        log(f"--- {n} layer(s)")
        per_layer[str(n)], keep[n] = run_layer(n, md, cfgs[n], root, out, kinds, seed, progress, log)

    metrics = {
        "experiment": KEY, "mode": md.name, "seed": seed, "layers": per_layer,
        "paper": {"hysteresis_fso": {str(k): {"before": v[0], "after": v[1]} for k, v in PAPER_HYST.items()},
                  "table2": {str(n): {str(o): {"mse": v[0], "r": v[1]} for o, v in t.items()} for n, t in PAPER_TABLE2.items()},
                  "table1_r": PAPER_TABLE1_R, "curves_kohm": _paper_curves()},
        "findings": findings(per_layer),
    }
    (out / "metrics.json").write_text(dumps(metrics))
    try:
        plots(out, keep, per_layer)
    except Exception as exc:  # noqa: BLE001  (a report without plots is still a report)
        log(f"plots failed: {exc}")
    (out / "report.md").write_text(report(metrics))
    log(f"wrote {out / 'report.md'} and {out / 'metrics.json'}")
    return metrics


def _paper_curves() -> dict[str, Any]:
    from sensors.fabric.calibrate import PAPER_CURVES

    return {str(n): {"coeffs": list(c.coeffs), "range_n": c.fitted_range_n, "samples": c.samples, "equation": c.equation}
            for n, c in PAPER_CURVES.items()}


def _split(seqs: list[Sequence], seed: int, frac_valid: float = 0.2) -> tuple[list[Sequence], list[Sequence]]:
    """Training episodes -> (train, valid) by whole episodes (valid drives LM's validation checks and early stopping)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(seqs))
    nv = max(1, int(round(frac_valid * len(seqs)))) if len(seqs) >= 2 else 0
    va = sorted((seqs[i] for i in perm[:nv]), key=lambda s: s.key)
    tr = sorted((seqs[i] for i in perm[nv:]), key=lambda s: s.key)
    return tr, va


LM_TRACE = ("mu", "grad_norm", "rejected_steps")  # bp_lm's per-epoch LM trace: "lm_trace", not "training"


def run_layer(n, md: Mode, cfgs, root: Path, out: Path, kinds, seed, progress, log):
    train_all, test, fps = make_data(root, n, cfgs, log)
    tr, va = _split(train_all, seed)
    f_max = float(cfgs[0].protocol.amplitude_max)
    poly = TargetPolynomial(POLY_DEGREE[n], f_max).fit(np.concatenate([s.extra["force"] for s in tr]),
                                                       np.concatenate([s.x[:, 0] for s in tr]))
    for s in (*train_all, *test):
        s.y = poly.predict(s.extra["force"])[:, None]
    units = {"resistance_measured": "ohm", "r_static": "ohm"}
    xs, ys = [s.x for s in tr], [s.y for s in tr]
    valid = ([s.x for s in va], [s.y for s in va])

    res: dict[str, Any] = {
        "dataset": fps, "split": {"train": [s.key for s in tr], "valid": [s.key for s in va], "test": [s.key for s in test]},
        "episode_seeds": {"train": [int(s.meta["seed"]) for s in train_all], "test": [int(s.meta["seed"]) for s in test]},
        "observations": {"train": sum(map(len, tr)), "valid": sum(map(len, va)), "test": sum(map(len, test))},
        "force_max_n": f_max,
        "target_poly": {"degree": POLY_DEGREE[n], "coeffs_kohm": poly.coeffs_kohm(),
                        "fit_rmse_kohm": M.rmse(np.concatenate([s.x[:, 0] for s in tr]) / KOHM,
                                                np.concatenate([s.y[:, 0] for s in tr]) / KOHM)},
        "raw": score(test, [s.x[:, 0] for s in test]),
        "models": {},
    }
    res["raw_train"] = score(tr, [s.x[:, 0] for s in tr])
    r = res["raw"]
    log(f"raw      hyst full {r['hyst_full_mean']:.1f} % FSO  loops max {r['hyst_loops_max']:.1f}  MSE {r['mse']:.4g} kOhm^2")
    comps = {}
    for kind in kinds:
        def assess(comp):
            rr = {"test": score(test, comp.predict([s.x for s in test])), "train": score(tr, comp.predict(xs)),
                  "context_observations": comp.context}
            if kind == "bp_lm":
                rr["lm_trace"] = {k: comp.history.get(k, []) for k in LM_TRACE}
            if kind == "tcn":  # each member alone (the seed spread the mean averages out; reported, not selected)
                pm = [comp.predict_members(s.x) for s in test]
                vm = [comp.predict_members(x) for x in valid[0]]
                rr["members"] = [{"seed": seed + j, **{k: v for k, v in score(test, [p[j] for p in pm]).items()
                                                      if k in ("mse", "r", "hyst_full_mean", "hyst_loops_max", "hyst_paper_mean")},
                                  "valid": {k: v for k, v in score(va, [p[j] for p in vm]).items()
                                            if k in ("mse", "hyst_full_mean", "hyst_loops_max")}}
                                 for j in range(len(comp.members))]
            return rr

        # ours: a seed ensemble of TCNs (members trained with seeds seed..seed+n-1, estimate = their mean)
        mk, mh = (("ensemble", {"member": "tcn", "n_members": md.tcn_members, "member_hparams": md.models[kind]})
                  if kind == "tcn" else (kind, md.models[kind]))
        comp, rr = fit_model(
            mk, mh, xs, ys, valid, seed=seed, progress=progress,
            fit_kw={"inputs": ["resistance_measured"], "targets": ["r_static"], "units": units}, assess=assess,
            latency_x=max(test, key=len).x, latency_n=md.latency_samples, history_skip=LM_TRACE,
            checkpoint=out / "checkpoints" / f"{PRESET[n]}-{kind}", dataset=fps["train"],
            checkpoint_extra=lambda r: {"experiment": KEY, "mode": md.name, "layers": n, "target_poly": res["target_poly"],
                                        "test": {k: v for k, v in r["test"].items() if k != "hyst_full_per_episode"}})
        res["models"][kind] = rr
        comps[kind] = comp
        t = rr["test"]
        log(f"{kind:8s} fit {rr['fit_seconds']:5.1f} s  hyst full {t['hyst_full_mean']:.1f} % FSO  loops max {t['hyst_loops_max']:.1f}  "
            f"MSE {t['mse']:.4g} kOhm^2  R {t['r']:.4f}")
    if "bp_lm" in kinds:
        res["table2"] = table2(md, xs, ys, valid, test, seed, units)
    return res, {"comps": comps, "test": test, "poly": poly, "f_max": f_max}


def table2(md: Mode, xs, ys, valid, test, seed, units) -> dict[str, Any]:
    """bp_lm trained on n random observations of the training episodes (hparam ``observations``), repeated
    ``obs_repeats`` times with different draws; median over repeats of MSE (kOhm^2) and R."""
    from learn.models import make_model

    hp = {**md.models["bp_lm"], "restarts": 1}
    out = {}
    for nobs in md.observations:
        runs = []
        for rep in range(md.obs_repeats):
            comp = make_model("bp_lm", **hp, observations=nobs)
            comp.fit(xs, ys, valid=valid, seed=seed + 17 * rep + 1, inputs=["resistance_measured"], targets=["r_static"],
                     units=units)
            idx = comp.history["observation_index"]
            Y = np.concatenate(ys)[:, 0]
            # in-sample: the network's output on its own n observations (features from the full episodes)
            P = np.concatenate([comp.predict(x)[:, 0] for x in xs])
            te = test
            pt_list = comp.predict([s.x for s in te])
            pt = np.concatenate([p[:, 0] for p in pt_list])
            yt = np.concatenate([s.y[:, 0] for s in te])
            runs.append({"train_mse": M.mse(Y[idx] / KOHM, P[idx] / KOHM), "train_r": M.pearson_r(Y[idx], P[idx]),
                         "test_mse": M.mse(yt / KOHM, pt / KOHM), "test_r": M.pearson_r(yt, pt),
                         **{k: v for k, v in zip(("test_hyst_full", "test_hyst_paper"),
                                                 (lambda sc: (sc["hyst_full_mean"], sc["hyst_paper_mean"]))(score(te, pt_list)))}})
        agg = {k: float(np.nanmedian([r_[k] for r_ in runs])) for k in runs[0]}
        out[str(nobs)] = {**agg, "runs": runs}
    return out


# ------------------------------------------------------------------------------------------------ findings / report

def findings(L: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {"bp_reduces_full_range_hysteresis": {}, "bp_reduces_worst_loop_hysteresis": {},
                           "bp_beats_mean_mse": {}, "best_model": {}}
    for n, r in L.items():
        m = r["models"]
        if "bp_lm" in m:
            out["bp_reduces_full_range_hysteresis"][n] = bool(m["bp_lm"]["test"]["hyst_full_mean"] < r["raw"]["hyst_full_mean"])
            out["bp_reduces_worst_loop_hysteresis"][n] = bool(m["bp_lm"]["test"]["hyst_loops_max"] < r["raw"]["hyst_loops_max"])
            if "mean" in m:
                out["bp_beats_mean_mse"][n] = bool(m["bp_lm"]["test"]["mse"] < m["mean"]["test"]["mse"])
        cand = {k: v["test"]["mse"] for k, v in m.items() if k != "mean"}
        if cand:
            out["best_model"][n] = min(cand, key=cand.get)
        t2 = r.get("table2", {})
        if t2:
            big = str(max(int(o) for o in t2))
            out.setdefault("bp_hyst_at_paper_data_size", {})[n] = {"observations": int(big),
                                                                  "hyst_full_mean": t2[big]["test_hyst_full"]}
        if "tcn" in m and "bp_lm" in m:
            a, b = m["tcn"]["test"], m["bp_lm"]["test"]
            out.setdefault("tcn_beats_bp_lm", {})[n] = {
                "mse": bool(a["mse"] < b["mse"]), "hyst_full_mean": bool(a["hyst_full_mean"] < b["hyst_full_mean"]),
                "hyst_loops_max": bool(a["hyst_loops_max"] < b["hyst_loops_max"]),
                **{k: bool(a[k] < b[k]) for k in ("hyst_paper_mean", "hyst_paper_worst") if k in a and k in b}}
    return out


def plots(out: Path, keep: dict[int, Any], L: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sensors.fabric.calibrate import PAPER_CURVES

    ns = sorted(keep)
    fig, axes = plt.subplots(1, len(ns), figsize=(4.2 * len(ns), 3.8), squeeze=False)
    for ax, n in zip(axes[0], ns):
        k = keep[n]
        s = max(k["test"], key=lambda q: len(loops(q.extra["level"])))
        a, _, b = loops(s.extra["level"])[0]
        sl = slice(a, b + 1)
        lv = s.extra["level"][sl]
        h = hysteresis(s.extra["level"], s.x[:, 0])["full_range"]
        ax.plot(lv, s.x[sl, 0] / KOHM, "-", color="0.45", lw=2.2, alpha=0.6, label=f"reading ({h:.1f} % FSO)")
        for kind, col in (("bp_lm", "tab:red"), ("tcn", "tab:blue")):
            if kind in k["comps"]:
                p = k["comps"][kind].predict(s.x)[:, 0]
                ax.plot(lv, p[sl] / KOHM, "-", color=col, lw=1,
                        label=f"{kind} ({hysteresis(s.extra['level'], p)['full_range']:.1f} %)")
        f = np.linspace(0, k["f_max"], 200)
        ax.plot(f, k["poly"].predict(f) / KOHM, "k--", lw=1, label="target (our fit)")
        c = PAPER_CURVES.get(n)
        if c:
            fm = np.linspace(0, c.monotone_range_n, 100)
            ax.plot(fm, c.r_ohm(fm) / KOHM, ":", color="tab:green", lw=1.2, label=f"paper {c.equation}")
        ax.set(xlabel="force (N)", ylabel="R (kΩ)", title=f"{n} layer(s): full-range cycle, test episode")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "loops.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    kinds = ["raw"] + [k for k in ORDER if any(k in L[str(n)]["models"] for n in ns)]
    w = 0.8 / len(kinds)
    for i, kind in enumerate(kinds):
        vals = [(L[str(n)]["raw"] if kind == "raw" else L[str(n)]["models"].get(kind, {}).get("test", {})).get("hyst_full_mean", np.nan)
                for n in ns]
        ax.bar(np.arange(len(ns)) + (i - (len(kinds) - 1) / 2) * w, vals, w, label=kind)
    ax.plot([-0.4], [PAPER_HYST[1][0]], "k^", label="paper 1 layer before")
    ax.plot([-0.2], [PAPER_HYST[1][1]], "kv", label="paper 1 layer after")
    ax.set(xticks=range(len(ns)), xticklabels=[f"{n} layer(s)" for n in ns], ylabel="max hysteresis error (% FSO)",
           title="full-range cycle, test episodes")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "hysteresis.png", dpi=110)
    plt.close(fig)

    if all("table2" in L[str(n)] for n in ns):
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        for n in ns:
            t = L[str(n)]["table2"]
            obs = sorted(int(o) for o in t)
            l, = axes[0].plot(obs, [t[str(o)]["test_mse"] for o in obs], "o-", label=f"{n} ours (test)")
            axes[0].plot(PAPER_OBS, [PAPER_TABLE2[n][o][0] for o in PAPER_OBS], "x--", color=l.get_color(), label=f"{n} paper")
            axes[1].plot(obs, [t[str(o)]["test_r"] for o in obs], "o-", color=l.get_color(), label=f"{n} ours (test)")
            axes[1].plot(PAPER_OBS, [PAPER_TABLE2[n][o][1] for o in PAPER_OBS], "x--", color=l.get_color(), label=f"{n} paper")
        axes[0].set(yscale="log", xlabel="observations", ylabel="MSE (kΩ²)", title="Table 2: MSE")
        axes[1].set(xlabel="observations", ylabel="R", title="Table 2: R")
        axes[0].legend(fontsize=6, ncol=2)
        fig.tight_layout()
        fig.savefig(out / "table2.png", dpi=110)
        plt.close(fig)

    n0 = ns[0]
    m = L[str(n0)]["models"].get("bp_lm")
    if m:
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
        ax[0].semilogy(m["loss_curve"]["train"], label="train")
        ax[0].semilogy(m["loss_curve"]["valid"], label="validation")
        ax[0].axvline(m["training"]["best_epoch"], color="k", lw=0.8, ls=":")
        ax[0].set(xlabel="epoch", ylabel="MSE (z-scored)", title=f"LM training, {n0} layer(s)")
        ax[0].legend(fontsize=8)
        ax[1].semilogy(m["lm_trace"]["mu"], label="mu")
        ax[1].semilogy(m["lm_trace"]["grad_norm"], label="|gradient|")
        ax[1].set(xlabel="epoch", title="damping and gradient")
        ax[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "lm_training.png", dpi=110)
        plt.close(fig)


def report(m: dict[str, Any]) -> str:
    L = m["layers"]
    ns = sorted(L, key=int)
    lines = [f"# fabric experiment ({m['mode']})", ""]
    lines += ["Training episodes (root seed {s}) and test episodes (root seed {t}, new random force sequences) are "
              "separate datasets; one observation per force level (the reading at the end of its 2 s dwell). "
              "Target: our polynomial R(F) (cubic for 1 layer, quartic otherwise) evaluated at the applied force."
              .format(s=m["seed"], t=m["seed"] + 1000), ""]
    rows = []
    for n in ns:
        r = L[n]
        rows.append([n, f"{r['observations']['train']} / {r['observations']['valid']} / {r['observations']['test']}",
                     len(r["split"]["train"]) + len(r["split"]["valid"]), len(r["split"]["test"]),
                     " ".join(f"{c:+.4g}" for c in r["target_poly"]["coeffs_kohm"]),
                     " ".join(f"{c:+.4g}" for c in m["paper"]["curves_kohm"][n]["coeffs"]),
                     fmt(r["target_poly"]["fit_rmse_kohm"])])
    lines.append(md_table(["layers", "observations train / valid / test", "train episodes", "test episodes",
                           "target R(F) ours (kOhm, highest power first)", "paper eqs. 6-9", "reading vs target RMSE (kOhm)"], rows))
    lines += ["", "## Max hysteresis error before and after (test episodes, % FSO)", ""]
    rows = []
    kinds = [k for k in ORDER if any(k in L[n]["models"] for n in ns)]
    for n in ns:
        r = L[n]
        p = PAPER_HYST.get(int(n))
        row = [n, f"{fmt(r['raw']['hyst_full_mean'], 1)} / {fmt(p[0], 1) if p else '–'}"]
        for k in kinds:
            t = r["models"].get(k, {}).get("test")
            pp = f" / {fmt(p[1], 1)}" if (p and k == "bp_lm") else (" / –" if k == "bp_lm" else "")
            row.append(f"{fmt(t['hyst_full_mean'], 1)}{pp}" if t else "–")
        row.append(" / ".join([fmt(r["raw"]["hyst_loops_max"], 1)] + [fmt(r["models"][k]["test"]["hyst_loops_max"], 1)
                                                                     for k in kinds if k in r["models"]]))
        rows.append(row)
    lines.append(md_table(["layers", "uncompensated ours / paper", *[f"{LABELS[k]}" + (" ours / paper" if k == "bp_lm" else "")
                                                                      for k in kinds],
                           "worst loop: " + " / ".join(["raw", *kinds])], rows))
    lines += ["", "Full-range cycle (0 -> F_max -> 0, the paper's figure), mean over test episodes; the last column is "
              "the worst of all loops (random minor loops included) of the test episodes. % FSO here is over the "
              "output span (ours); the paper's definition (over the highest output value) follows.", ""]
    rows = []
    for n in ns:
        r = L[n]
        p = PAPER_HYST.get(int(n))
        row = [n, f"{fmt(r['raw'].get('hyst_paper_mean'), 1)} / {fmt(p[0], 1) if p else '–'}"]
        for k in kinds:
            t = r["models"].get(k, {}).get("test")
            pp = f" / {fmt(p[1], 1)}" if (p and k == "bp_lm") else (" / –" if k == "bp_lm" else "")
            row.append(f"{fmt(t.get('hyst_paper_mean'), 1)}{pp}" if t else "–")
        rows.append(row)
    lines += ["### Same, referenced to the highest output value (the paper's definition, sect. 3.3; %)", ""]
    lines.append(md_table(["layers", "uncompensated ours / paper", *[f"{LABELS[k]}" + (" ours / paper" if k == "bp_lm" else "")
                                                                      for k in kinds]], rows))
    lines.append("")
    lines += ["## Models on the test episodes (MSE in kOhm^2, R Pearson)", ""]
    rows = []
    for n in ns:
        r = L[n]
        rows.append([n, LABELS["raw"], fmt(r["raw"]["mse"], 4), fmt(r["raw"]["r"], 4), fmt(r["raw"]["rmse"]), "–", "–"])
        for k in ["mean", *ORDER]:
            if k in r["models"]:
                x = r["models"][k]
                rows.append([n, LABELS[k], fmt(x["test"]["mse"], 4), fmt(x["test"]["r"], 4), fmt(x["test"]["rmse"]),
                             f"{fmt(x['train']['mse'], 4)} / {fmt(x['train']['r'], 4)}", f"{x['fit_seconds']:.1f}"])
    lines.append(md_table(["layers", "model", "MSE test", "R test", "RMSE (kOhm)", "train MSE / R", "fit (s)"], rows))
    if all("table2" in L[n] for n in ns):
        lines += ["", "## Appendix Table 2: BP network by layers and observations (ours | paper)", ""]
        rows = []
        for n in ns:
            t = L[n]["table2"]
            for o in sorted(t, key=int):
                p = PAPER_TABLE2.get(int(n), {}).get(int(o))
                rows.append([n, o, f"{t[o]['train_mse']:.3g} / {t[o]['train_r']:.4f}",
                             f"{t[o]['test_mse']:.3g} / {t[o]['test_r']:.4f}", fmt(t[o]["test_hyst_full"], 1),
                             f"{p[0]:.3g} / {p[1]:.4f}" if p else "–"])
        lines.append(md_table(["layers", "observations", "ours, on its observations: MSE / R", "ours, test episodes: MSE / R",
                               "test max hyst. (% FSO)", "paper MSE / R"], rows))
        lines += ["", "Median over repeats with different random draws of the observations (metrics.json has each run)."]
    F = m["findings"]
    lines += ["", "## The paper's findings, checked", ""]
    lines.append("- BP network reduces the max hysteresis error (full-range cycle): "
                 + ", ".join(f"{n} layer(s) {'yes' if v else 'no'}" for n, v in F["bp_reduces_full_range_hysteresis"].items()) + ".")
    lines.append("- ... and the worst loop: "
                 + ", ".join(f"{n} layer(s) {'yes' if v else 'no'}" for n, v in F["bp_reduces_worst_loop_hysteresis"].items()) + ".")
    if F.get("tcn_beats_bp_lm"):
        lines.append("- TCN (ours) vs the BP network: " + "; ".join(
            f"{n} layer(s): " + ", ".join(f"{k} {'better' if v else 'not better'}" for k, v in d.items())
            for n, d in F["tcn_beats_bp_lm"].items()) + ".")
    if F.get("bp_hyst_at_paper_data_size"):
        lines.append("- BP network trained on the paper's amount of data (Table 2's largest column), test max hysteresis: "
                     + ", ".join(f"{n} layer(s) {fmt(v['hyst_full_mean'], 1)} % FSO ({v['observations']} observations)"
                                 for n, v in F["bp_hyst_at_paper_data_size"].items()) + " (paper, 1 layer: 13.5 %).")
    lines.append("- Lowest test MSE: " + ", ".join(f"{n} layer(s) {k}" for n, k in F["best_model"].items()) + ".")
    lines += ["", "![loops](loops.png)", "", "![hysteresis](hysteresis.png)", "", "![table 2](table2.png)", "",
              "![LM training](lm_training.png)", ""]
    lines += ["## Where we differ from the paper, and why", "", DIFFERENCES.strip(), ""]
    if m["mode"] != "full":
        lines += [f"This is the **{m['mode']}** configuration (fewer episodes; see `learn/experiments/fabric.py`, MODES). "
                  "`piezotwin experiment fabric` (no --quick) uses the presets' episode counts.", ""]
    return "\n".join(lines)


DIFFERENCES = """
- **The sensor is simulated** (`piezotwin characterize fabric_N`): Prony creep, a Prandtl-Ishlinskii play bank and a
  Kirchhoff/Holm stack law calibrated to the paper's loading curves (eqs. 6-9), read by a 2-wire multimeter. The
  play thresholds of 3-12 layers are estimates (the paper gives a hysteresis figure for 1 layer only).
- **Target.** The paper fits its polynomial to the hysteresis curve and does not say which branch; ours is a least
  squares fit over both branches of the training readings (the loop's midline), so it sits between loading and
  unloading and differs from eqs. 6-9, which our loading branch follows by calibration. Eqs. 8-9 are fitted up to
  15-20 N but turn upward past 9.09 / 7.54 N; our quartics are fitted to our data over the whole range.
- **What "max hysteresis error" is.** Ours: max |y_up - y_down| at equal nominal force over the output span of the
  full-range cycle, for the raw reading and for the network's output alike (the paper refers the error to "the
  highest output value"; see the fabric section of README.md). Taken on held-out test episodes.
- **Every press differs (issue 13).** A hand-loaded knit is seated differently at every press: each press draws
  its engaged contact area (lognormal, sigma 5 %) and the part of its peak compaction the knit keeps on release
  (the knit set: a Beta draw in [0, 1) of mean ~0.16 and coefficient of variation 0.75, an estimate bounded by
  Kawabata's compression resilience of knits), from the episode seed; the
  set relaxes over ~1 min and carries into the next press (`sensor.press`, scenes/fabric_config.py). The mean set
  fraction is fitted so that the mean loop of repeated 1-layer cycles has the paper's 24.2 % (`piezotwin calibrate
  fabric`). The loop a press will draw is not visible in (R_t, R_{t-1}), so the paper's BP net keeps part of it:
  with all our training data it leaves ~9 % of the highest output on the 1-layer full-range cycle (paper 13.5 %),
  where it left ~1 % when every press was alike. No noise is added to the output beyond the multimeter's.
- **Uncompensated figure.** Characterization reports the paper's figure on the mean loop of repeats (the paper
  averages 5); this table reports the mean over test episodes of each single cycle's figure, which scatters with
  the press's draw (single 1-layer repeats: 5-95 % range ~11-40 %, median 23 %, over 200 seeds). 3-12 layers carry the 1-layer set fraction (same
  fabric; the paper gives no hysteresis figure for them), which gives them wider loops than 1 layer.
- **How much the BP network can remove.** Its only memory is one previous reading. At equal (R_t, R_{t-1}) a
  loading and an unloading observation differ only in the sign of the last step, so the net can undo the part of
  the loop that the last step reveals (branch direction, creep since the last level); the rest of the
  Prandtl-Ishlinskii memory (where the last turn was) is invisible to it, which is why its worst minor loop keeps
  more error than the full-range cycle. The TCN sees the history of readings (and ln R beside R) and removes more.
- **Ours reads a play-operator bank (issue 13).** Without it, the full-range loop that our TCN left at 6 and 12
  layers had its largest gap at the low-force end (the first few percent of the force range, where R is highest
  and steepest): the unloading branch of a press with a large knit set read low there, and in the other presses
  the unloading branch was over-corrected near 1 N, so on the paper's definition (gap over the highest output)
  the TCN tied or lost to the BP net at 6 and 12 layers. The reading's turning points carry that memory (how far
  the last press went, whether it is rising or falling), and a receptive field of past readings holds it only
  while the turning point is inside the window; a Prandtl-Ishlinskii bank of play operators on ln R, the classic
  inverse-hysteresis compensator's state (Kuhnen 2003), holds it for as long as the loop lasts, with the
  return-point memory of the sensor's own play bank. Six widths, 2-50 % of the training ln R span, fixed before
  any test and equal for every layer count and mode (learn.models.tcn, ``play_widths``).
- **What is left at 6 and 12 layers.** With the bank, ours wins every metric at 1 and 3 layers by a wide margin;
  at 6 and 12 layers the full-range figure of ours and of the BP net move together, test episode by test
  episode: in both, the largest gap stays on the unloading branch in the first few percent of the force range,
  over-corrected for presses that kept less set than the mean and under-corrected for the one that kept most.
  That press-to-press set draw is not identifiable from the readings before the branch ends, so both nets apply
  the mean set there, and the difference between them is within the spread of 4 test episodes: the full run's
  12-layer figures moved by more between training on 8 and on 16 episodes (the full mode now uses 16 for every
  layer count; the 8-episode run is kept in the results file under ``superseded``) than they differ between the
  two nets.
- **Ours is a seed ensemble of TCNs.** One TCN trained on 6 episodes and early-stopped on 1 validation episode
  lands far from its neighbours at the rare operating points of the worst loop (a large knit set followed by a
  minor loop): with the earlier, unbounded set draws a single TCN lost the worst-loop metric to the BP net on 3-12
  layers while winning the mean ones. Averaging members trained with different seeds (5 in quick/full, as the
  velostat experiment does) removes that seed spread; metrics.json keeps each member's scores (reported, not
  selected).
- **Quick mode** uses coarser force steps for 3, 6 and 12 layers (0.2 / 0.4 / 0.5 N, ~40 levels up the full
  range): fewer dwells mean less creep per newton, so the uncompensated loop is wider there than at the paper's
  0.1 N steps (e.g. 6 layers: ~34 % against ~25 %). The full mode uses 0.1 N everywhere.
- **Table 2 is not self-consistent in the paper.** For a least-squares fit MSE ~ (1 - R^2) var(target); with the
  1-layer target's variance (~0.4 kOhm^2 over 0-2 N, eq. 6) R = 0.996-0.9997 implies MSE 1e-4 to 3e-3, but the
  printed MSEs range 1e-4 to 5e-2 with no relation to R (14 observations: MSE 0.0515 with R 0.9992, 80x apart;
  6 and 29 observations: MSE ~1e-4 with R 0.996 / 0.999, 30x / 8x apart; the 3-layer 14-observation row repeats
  the 1-layer one; 12 layers, 18 observations prints MSE 0.9985 beside R 0.9993). Within a factor 3 only the
  rows 1 layer / 11 observations, 3 layers / 6 and 11, 6 layers / 11 and 46, 12 layers / 6 are consistent, if
  the MSE is on the paper's kOhm. R >= 0.997 is also inconsistent with the paper's own 13.5 % residual
  hysteresis (an error of ~0.4 kOhm at mid-force gives R ~ 0.98 on the 1-layer target), so Table 2 reads as
  in-sample fits on few points; our in-sample R (column "ours, on its observations") sits at 0.88-0.999, lower
  where the per-press variation enters, and our MSE is within ~3-4x of the consistent 1-layer row.
- **Table 2, definitions.** The paper does not define "observation"; we read it as the number of training observations (random
  (R_t, R_{t-1}) -> target pairs drawn from the training episodes), with LM's validation checks on separate
  episodes, and report MSE/R both on those observations (comparable to the paper's, which look in-sample: R near 1)
  and on the test episodes. MSE is in kOhm^2 (the paper prints no unit; we read R as kOhm).
- **Training details the paper leaves open**: z-scored inputs/target (MATLAB: mapminmax), Nguyen-Widrow initial
  weights, best of several seeded initialisations on the validation SSE, trainlm's mu schedule (1e-3, x0.1, x10).
"""

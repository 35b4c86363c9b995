"""cnt_pdms experiment (paper 002): stacked LSTM + baselines + our TCN, Tables 3 and 4 beside the paper's.

  data     simulate.generation.run.generate on the cnt_pdms preset (reused when the folder already holds it):
           displacement-controlled sinusoids at 0.1/0.5/1/2 Hz, random amplitude, each episode on a fresh sample
           (Mullins damage 0: sensors/cnt_pdms/model.py); input `resistance_measured` (ohm, zero-phase
           filtered; z-scored, so equal to the paper's Delta R up to the offset),
           label `force` (N, the viscoelastic reference), drive `target` (m, for loop analysis).
  split    episodes, pooled over frequencies and amplitudes, 70/10/20 train/valid/test stratified by
           frequency: the paper's 80/20 with a tenth carved out of the 80 for early stopping.
  freq set Table 4 needs several held-out episodes per frequency, which the 20 % share of a small dataset does not
           give (quick: 1-2 per frequency). A second, test-only dataset holds ``freq_test_episodes`` episodes at each
           frequency (root seed seed + 1000 + index of the frequency: new amplitudes and samples, never trained on);
           every model is scored on it per frequency beside the split's test share. Its size is fixed per mode.
  models   linear, cubic, mlp (static: current sample); gru, lstm (window 50); tcn (ours); mean (trivial).
  report   report.md, metrics.json, loops.png, traces.png, frequency.png, checkpoints/<model>/.

Modes: "full" = the preset's data and the paper's training budget (<= 200 epochs, patience 15);
"quick" = 24 two-cycle episodes on a 5 x 5 grid, capped epochs (a few minutes on 2 cores);
"tiny" = seconds, for tests only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from learn.data import (
    Sequence,
    dataset_fingerprint,
    dumps,
    group_by,
    load_sequences,
    stratified_split,
)
from learn.experiments.common import (
    batch_latency,
    evaluate,
    fit_model,
    fmt,
    make_data,
    md_table,
    raw_hysteresis,
    select_mode,
    single_thread,
)

KEY = "cnt_pdms"
INPUTS, TARGETS, DRIVE = ["resistance_measured"], ["force"], "target"
ORDER = ["linear", "cubic", "mlp", "gru", "lstm", "tcn"]
LABELS = {"mean": "Mean (trivial)", "linear": "Linear regression", "cubic": "Polynomial (3rd order)", "mlp": "MLP",
          "gru": "GRU (1 layer)", "lstm": "Stacked LSTM (paper's model)", "tcn": "TCN (ours)"}

# Paper 002, Table 3 (MAE N, RMSE N, R^2, max error %, inference ms) and Table 4 (LSTM per frequency).
PAPER_TABLE3 = {
    "linear": (0.742, 0.915, 0.764, 14.8, 0.5),
    "cubic": (0.521, 0.684, 0.825, 11.2, 0.8),
    "mlp": (0.315, 0.428, 0.882, 8.5, 2.1),
    "gru": (0.112, 0.165, 0.965, 3.1, 10.4),
    "lstm": (0.086, 0.134, 0.988, 1.8, 14.8),
}
PAPER_TABLE4 = {0.1: (0.052, 0.078, 0.992, 1.1), 0.5: (0.086, 0.134, 0.988, 1.8),
                1.0: (0.098, 0.155, 0.984, 2.2), 2.0: (0.142, 0.198, 0.975, 3.1)}
PAPER_RAW_HYST = 12.4  # % FSO, uncompensated (sect. 3.1)

PAPER_TRAIN = {"lr": 1e-3, "batch_size": 64, "max_epochs": 200, "patience": 15}


@dataclass
class Mode:
    name: str
    scene: list[str]
    models: dict[str, dict[str, Any]]
    latency_samples: int = 300
    split: tuple[float, float, float] = (0.7, 0.1, 0.2)
    freq_test_episodes: int = 0  # per frequency, in the test-only frequency dataset (0: none)


def _modes() -> dict[str, Mode]:
    full = Mode("full", [], {"mean": {}, "linear": {}, "cubic": {}, "mlp": dict(PAPER_TRAIN), "gru": dict(PAPER_TRAIN),
                             "lstm": dict(PAPER_TRAIN), "tcn": {"max_epochs": 200, "patience": 15}}, freq_test_episodes=4)
    q_scene = ["pad.taxels_x=5", "pad.taxels_y=5", "protocol.cycles=2", "generation.episodes=24",
               "generation.episodes_per_shard=12", "generation.threads=1"]
    quick = Mode("quick", q_scene, {
        "mean": {}, "linear": {}, "cubic": {},
        "mlp": {"max_epochs": 40, "patience": 10, "max_batches_per_epoch": 60},
        # the paper trains its recurrent nets alike (Table 2: one Adam step, batch, epoch cap and early stopping), so the
        # GRU and the LSTM share one capped budget here: 40 x 40 batches, patience 10, a 3x larger step than the paper's
        # 1e-3 (25 x 40 batches at 1e-3 left the stacked LSTM worse than linear). Issue 13: the GRU had 25 epochs and
        # patience 8 (1.3 passes over the data) and stopped at epoch 12, best at 3, its training loss still falling.
        "gru": {"max_epochs": 40, "patience": 10, "max_batches_per_epoch": 40, "valid_stride": 2, "lr": 3e-3},
        "lstm": {"max_epochs": 40, "patience": 10, "max_batches_per_epoch": 40, "valid_stride": 2, "lr": 3e-3},
        "tcn": {"max_epochs": 60, "patience": 15},
    }, freq_test_episodes=4)
    t_scene = ["pad.taxels_x=3", "pad.taxels_y=3", "protocol.cycles=1", "generation.episodes=12",
               "generation.episodes_per_shard=12", "generation.threads=1"]
    tiny = Mode("tiny", t_scene, {
        "mean": {}, "linear": {}, "cubic": {},
        "mlp": {"max_epochs": 10, "patience": 5},
        "gru": {"max_epochs": 3, "patience": 3, "train_stride": 4, "hidden": [16]},
        "lstm": {"max_epochs": 3, "patience": 3, "train_stride": 4, "hidden": [32, 16]},
        "tcn": {"max_epochs": 15, "patience": 5, "channels": 16},
    }, latency_samples=60)
    return {m.name: m for m in (full, quick, tiny)}


MODES = _modes()


def scene(mode: Mode, overrides: list[str], seed: int):
    """The scene config of a mode (raises scenes.ConfigError, a ValueError, on a bad override)."""
    from scenes import load_scene

    return load_scene("cnt_pdms", [*mode.scene, f"generation.root_seed={seed}", *overrides])


def freq_scenes(mode: Mode, overrides: list[str], seed: int) -> dict[float, Any]:
    """The test-only frequency datasets: frequency -> scene config (``freq_test_episodes`` episodes at that
    frequency, root seed seed + 1000 + its index); empty when the mode has none."""
    from scenes import load_scene

    if mode.freq_test_episodes <= 0:
        return {}
    base = scene(mode, overrides, seed)
    n = int(mode.freq_test_episodes)
    return {float(f): load_scene("cnt_pdms", [*mode.scene, *overrides, f"protocol.frequencies_hz=[{f}]",
                                              f"generation.episodes={n}", f"generation.episodes_per_shard={n}",
                                              f"generation.root_seed={seed + 1000 + i}"])
            for i, f in enumerate(base.protocol.frequencies_hz)}


@single_thread
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
) -> dict[str, Any]:
    """Generate (or reuse) the data, train every model, evaluate on the held-out episodes, write the report."""
    md = select_mode(MODES, mode, models)
    cfg = scene(md, list(overrides or []), seed)  # validate before anything is written
    fcfgs = freq_scenes(md, list(overrides or []), seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    root = Path(data_dir) if data_dir else out / "data"
    data = make_data(root, cfg, log)
    # the frequency sets live beside the dataset, not inside its tree (its fingerprint covers the tree)
    fdata = {f: make_data(root.parent / f"{root.name}-freq-test" / f"{f:g}hz", c, log) for f, c in fcfgs.items()}
    fte = {f: load_sequences(d, INPUTS, TARGETS, extra=[DRIVE]) for f, d in fdata.items()}
    seqs = load_sequences(data, INPUTS, TARGETS, extra=[DRIVE])
    split = stratified_split(seqs, "frequency_hz", seed, md.split)
    tr, va, te = split["train"], split["valid"], split["test"]
    units = seqs[0].units
    fp = dataset_fingerprint(data)
    kinds = [k for k in ["mean", *ORDER] if k in md.models and (models is None or k in models or k == "mean")]

    results: dict[str, Any] = {}
    comps = {}
    longest = max(te, key=len)
    for kind in kinds:
        def assess(comp):
            return {"test": evaluate(comp, te, DRIVE), "context_samples": comp.context,
                    "per_frequency": {str(f): evaluate(comp, g, DRIVE) for f, g in group_by(te, "frequency_hz").items()},
                    "batch_ms_per_sample": batch_latency(comp, longest.x),
                    **({"freq_test": {f"{f:g}": evaluate(comp, g, DRIVE) for f, g in fte.items()}} if fte else {})}

        comp, r = fit_model(kind, md.models[kind], [s.x for s in tr], [s.y for s in tr],
                            ([s.x for s in va], [s.y for s in va]), seed=seed, progress=progress,
                            fit_kw={"inputs": INPUTS, "targets": TARGETS, "units": units}, assess=assess,
                            latency_x=longest.x, latency_n=md.latency_samples, checkpoint=out / "checkpoints" / kind,
                            dataset=fp, checkpoint_extra=lambda r: {"experiment": KEY, "mode": mode, "test": r["test"]})
        results[kind] = r
        comps[kind] = comp
        t = r["test"]
        log(f"{kind:7s} fit {r['fit_seconds']:6.1f} s  MAE {t['mae']:.4f} N  RMSE {t['rmse']:.4f} N  R2 {t['r2']:.4f}  "
            f"hyst {t.get('hyst_mean', float('nan')):.2f} %FSO  stream {r['latency']['median_ms']:.3f} ms")

    raw = {"all": raw_hysteresis(te, DRIVE)}
    raw.update({str(f): raw_hysteresis(g, DRIVE) for f, g in group_by(te, "frequency_hz").items()})
    metrics = {
        "experiment": KEY, "mode": mode, "seed": seed, "dataset": fp,
        "split": {k: [s.key for s in v] for k, v in split.items()},
        "split_counts": {k: {str(f): len(g) for f, g in group_by(v, "frequency_hz").items()} for k, v in split.items()},
        "raw_hysteresis": raw, "models": results,
        **({"freq_test": {"episodes_per_frequency": md.freq_test_episodes,
                          "datasets": {f"{f:g}": dataset_fingerprint(d) for f, d in fdata.items()},
                          "raw_hysteresis": {f"{f:g}": raw_hysteresis(g, DRIVE) for f, g in fte.items()}}} if fte else {}),
        "paper": {"table3": PAPER_TABLE3, "table4": {str(k): v for k, v in PAPER_TABLE4.items()},
                  "raw_hysteresis_fso": PAPER_RAW_HYST},
        "findings": findings(results),
    }
    (out / "metrics.json").write_text(dumps(metrics))
    try:
        plots(out, comps, te, results)
    except Exception as exc:  # noqa: BLE001  (a report without plots is still a report)
        log(f"plots failed: {exc}")
    (out / "report.md").write_text(report(metrics))
    log(f"wrote {out / 'report.md'} and {out / 'metrics.json'}")
    return metrics


def findings(results: dict[str, Any]) -> dict[str, Any]:
    """The paper's qualitative claims, checked on our numbers."""
    order = [k for k in ORDER[:5] if k in results]
    rmse = [results[k]["test"]["rmse"] for k in order]
    pairs = {f"{a}>{b}": bool(x > y) for a, b, x, y in zip(order, order[1:], rmse, rmse[1:])}
    out: dict[str, Any] = {"paper_order": order, "rmse_in_paper_order": rmse, "pairwise_rmse_decreasing": pairs,
                           "paper_order_holds": all(pairs.values())}
    for k in ("lstm", "tcn"):
        if k in results:
            pf = results[k]["per_frequency"]
            fs = sorted(pf, key=float)
            m = [pf[f]["mae"] for f in fs]
            out[f"{k}_mae_rises_with_frequency"] = bool(all(a <= b for a, b in zip(m, m[1:])))
            out[f"{k}_mae_by_frequency"] = dict(zip(fs, m))
            ft = results[k].get("freq_test")
            if ft:
                fs = sorted(ft, key=float)
                m = [ft[f]["mae"] for f in fs]
                out[f"{k}_freq_test_mae_rises_with_frequency"] = bool(all(a <= b for a, b in zip(m, m[1:])))
                out[f"{k}_freq_test_mae_by_frequency"] = dict(zip(fs, m))
    if "tcn" in results:
        best_paper = min((k for k in ORDER[:5] if k in results), key=lambda k: results[k]["test"]["rmse"], default=None)
        if best_paper:
            a, b = results["tcn"]["test"], results[best_paper]["test"]
            out["best_paper_model"] = best_paper
            out["tcn_beats_best_paper_model"] = {m: bool(a[m] < b[m]) if m != "r2" else bool(a[m] > b[m])
                                                 for m in ("mae", "rmse", "r2", "hyst_mean")}
    return out


def plots(out: Path, comps: dict, te: list[Sequence], results: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from learn import metrics as M

    by_f = group_by(te, "frequency_hz")
    f_show = 0.5 if 0.5 in by_f else sorted(by_f)[len(by_f) // 2]
    s = max(by_f[f_show], key=lambda q: q.meta.get("amplitude", 0))
    cyc = M.cycle_slices(s.extra[DRIVE])
    c = cyc[-1] if cyc else slice(None)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(s.x[c, 0], s.y[c, 0], "k")
    ax[0].set(xlabel=f"{INPUTS[0]} ({s.units[INPUTS[0]]})", ylabel="force (N)",
              title=f"uncompensated, {f_show} Hz: {M.hysteresis_error_fso(s.y[c, 0], s.x[c, 0], s.extra[DRIVE][c]):.1f} % FSO")
    for k in ("linear", "lstm", "tcn"):
        if k in comps:
            p = comps[k].predict(s.x)[c, 0]
            ax[1].plot(p, s.y[c, 0], label=f"{k}: {M.hysteresis_error_fso(s.y[c, 0], p, s.extra[DRIVE][c]):.1f} % FSO")
    lim = [0, float(s.y[c, 0].max()) * 1.05]
    ax[1].plot(lim, lim, "k:", lw=0.8)
    ax[1].set(xlabel="estimated force (N)", ylabel="reference force (N)", title="after compensation")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "loops.png", dpi=110)
    plt.close(fig)

    s2 = max(by_f[max(by_f)], key=lambda q: q.meta.get("amplitude", 0))
    fig, ax = plt.subplots(figsize=(9, 3.5))
    t = s2.extra.get("time", np.arange(len(s2)) / 100.0)
    ax.plot(t, s2.y[:, 0], "k", lw=2, label="reference")
    for k in ("linear", "mlp", "lstm", "tcn"):
        if k in comps:
            ax.plot(t, comps[k].predict(s2.x)[:, 0], lw=1, label=k)
    ax.set(xlabel="sample time (s)" if "time" in s2.extra else "time (s, 100 Hz)", ylabel="force (N)",
           title=f"held-out episode at {max(by_f)} Hz")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "traces.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    for k, r in results.items():
        if k == "mean":
            continue
        fs = sorted(r["per_frequency"], key=float)
        ax.plot([float(f) for f in fs], [r["per_frequency"][f]["mae"] for f in fs], "o-", label=k)
    ax.plot(list(PAPER_TABLE4), [v[0] for v in PAPER_TABLE4.values()], "k--", label="paper LSTM")
    ax.set(xscale="log", xlabel="loading frequency (Hz)", ylabel="MAE (N)", title="error vs frequency (held-out)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "frequency.png", dpi=110)
    plt.close(fig)


def report(m: dict[str, Any]) -> str:
    R, P3, P4 = m["models"], PAPER_TABLE3, PAPER_TABLE4
    lines = [f"# cnt_pdms experiment ({m['mode']})", ""]
    ds = m["dataset"]
    sc = m["split_counts"]
    lines += [f"Data: `{ds['path']}` ({ds['total_episodes']} episodes, dataset sha256 `{str(ds['dataset_sha256'])[:12]}`). "
              f"Held-out episodes per frequency: {sc['test']}; train {sc['train']}; valid {sc['valid']}. Seed {m['seed']}.", ""]
    lines += ["## Table 3: models on the held-out episodes (ours | paper)", ""]
    rows = []
    for k in ["mean", *ORDER]:
        if k not in R:
            continue
        t, p = R[k]["test"], P3.get(k)
        pp = lambda i: fmt(p[i], 3 if i < 3 else 1) if p else "–"
        rows.append([LABELS[k], f"{fmt(t['mae'])} / {pp(0)}", f"{fmt(t['rmse'])} / {pp(1)}", f"{fmt(t['r2'])} / {pp(2)}",
                     f"{fmt(t.get('hyst_mean'), 1)} / {pp(3)}", f"{fmt(R[k]['latency']['median_ms'], 3)} / {pp(4)}",
                     f"{R[k]['fit_seconds']:.1f}"])
    lines.append(md_table(["model", "MAE (N) ours / paper", "RMSE (N)", "R^2", "max hyst. error (% FSO)",
                           "inference (ms/sample)", "fit (s)"], rows))
    raw = m["raw_hysteresis"]["all"]
    lines += ["", f"Uncompensated sensor: max hysteresis error {fmt(raw['hyst_mean'], 1)} % FSO (mean over "
              f"{raw['n_cycles']} held-out cycles; worst {fmt(raw['hyst_worst'], 1)}); paper {PAPER_RAW_HYST} %.", ""]
    lines += ["## Table 4: per loading frequency (held-out)", ""]
    rows = []
    for f in sorted({f for r in R.values() for f in r["per_frequency"]}, key=float):
        p = P4.get(float(f))
        for k in ("lstm", "tcn"):
            if k in R and f in R[k]["per_frequency"]:
                t = R[k]["per_frequency"][f]
                rows.append([f, k, fmt(t["mae"]), fmt(t["rmse"]), fmt(t["r2"]), fmt(t.get("hyst_mean"), 1),
                             fmt(m["raw_hysteresis"].get(f, {}).get("hyst_mean"), 1),
                             " / ".join(fmt(v, 3 if i < 3 else 1) for i, v in enumerate(p)) if p and k == "lstm" else ""])
    lines.append(md_table(["f (Hz)", "model", "MAE (N)", "RMSE (N)", "R^2", "max hyst. (% FSO)",
                           "uncompensated (% FSO)", "paper LSTM MAE / RMSE / R^2 / max"], rows))
    if "freq_test" in m:
        ft = m["freq_test"]
        lines += ["", f"### Table 4 on the frequency test set ({ft['episodes_per_frequency']} held-out episodes per "
                  "frequency, a separate dataset never trained on)", ""]
        rows = []
        for f in sorted(ft["raw_hysteresis"], key=float):
            p = P4.get(float(f))
            for k in ("gru", "lstm", "tcn"):
                t = R.get(k, {}).get("freq_test", {}).get(f)
                if t:
                    rows.append([f, k, fmt(t["mae"]), fmt(t["rmse"]), fmt(t["r2"]), fmt(t.get("hyst_mean"), 1),
                                 fmt(ft["raw_hysteresis"][f].get("hyst_mean"), 1),
                                 " / ".join(fmt(v, 3 if i < 3 else 1) for i, v in enumerate(p)) if p and k == "lstm" else ""])
        lines.append(md_table(["f (Hz)", "model", "MAE (N)", "RMSE (N)", "R^2", "max hyst. (% FSO)",
                               "uncompensated (% FSO)", "paper LSTM MAE / RMSE / R^2 / max"], rows))
    F = m["findings"]
    lines += ["", "## The paper's qualitative findings, checked", ""]
    lines.append(f"- Error order linear > cubic > MLP > GRU > LSTM (RMSE): **{'holds' if F['paper_order_holds'] else 'does not fully hold'}** "
                 f"({', '.join(f'{k} {v}' for k, v in F['pairwise_rmse_decreasing'].items())}).")
    for k in ("lstm", "tcn"):
        if f"{k}_mae_rises_with_frequency" in F:
            mm = ", ".join(f"{f} Hz {v:.3f}" for f, v in F[f"{k}_mae_by_frequency"].items())
            lines.append(f"- {k} error rising with frequency: **{'yes' if F[f'{k}_mae_rises_with_frequency'] else 'not monotone'}** (MAE {mm}).")
        if f"{k}_freq_test_mae_rises_with_frequency" in F:
            mm = ", ".join(f"{f} Hz {v:.3f}" for f, v in F[f"{k}_freq_test_mae_by_frequency"].items())
            lines.append(f"- ... on the frequency test set: **{'yes' if F[f'{k}_freq_test_mae_rises_with_frequency'] else 'not monotone'}** "
                         f"(MAE {mm}).")
    if "tcn_beats_best_paper_model" in F:
        b = F["tcn_beats_best_paper_model"]
        lines.append(f"- TCN (ours) vs the best paper model here ({F['best_paper_model']}): "
                     + ", ".join(f"{k} {'better' if v else 'not better'}" for k, v in b.items()) + ".")
    lines += ["", "![loops](loops.png)", "", "![traces](traces.png)", "", "![frequency](frequency.png)", ""]
    lines += ["## Where we differ from the paper, and why", "", DIFFERENCES.strip(), ""]
    if m["mode"] != "full":
        lines += [f"This is the **{m['mode']}** configuration: few, short episodes on a small taxel grid and capped "
                  "epochs (see `learn/experiments/cnt_pdms.py`, MODES). The recurrent models are under-trained relative to "
                  "the paper's 200-epoch budget; `piezotwin experiment cnt_pdms` (no --quick) runs the paper's budget.", ""]
    return "\n".join(lines)


DIFFERENCES = """
- **The sensor.** Ours is simulated (`piezotwin characterize cnt_pdms`): a percolating, tunneling CNT network
  (sensors/percolation.py) whose strain gain is fitted to the paper's linear-regression R^2 and whose play bank is
  fitted to the paper's 12.4 % FSO at 0.5 Hz (`piezotwin calibrate cnt_pdms`); network kinetics, Prony terms and
  Mullins-type damage of a fresh sample are literature estimates. The material carries the hysteresis: the
  Butterworth runs zero-phase (sect. 2.2), so it adds no lag. Our R(F) is a smooth, strongly nonlinear map and
  its loops are about as wide as the paper's, so the flexible static models (cubic, MLP) recover more than the
  paper's (which face a real composite with session-to-session variation that we do not model), while the
  linear baseline matches the paper's.
- **Max error.** Per cycle we take the paper's definition (max force gap between the loading and unloading
  branches at equal output, over that cycle's peak force) and report the mean over held-out cycles (the worst
  cycle is in metrics.json). The paper does not say how it aggregates; its uncompensated 12.4 % matches our
  0.5 Hz figure, not the pooled one.
- **Split.** We split whole episodes, stratified by frequency, 70/10/20 (the 10 % validation for early
  stopping is taken from the paper's 80 % training share), so no cycle of a test episode is seen in training.
  The paper pooled cycles before an 80/20 split.
- **Inference time.** Ours is the per-sample latency of the streaming compensator (state carried, one
  sample in, one estimate out) on one CPU core, median over a held-out episode; the paper's 14.8 ms is for an
  unspecified machine and batch. Our LSTM streams by re-running the 50-sample window each sample (exactly the
  batch model); the TCN keeps per-layer ring buffers and does O(1) work per sample.
- **Quick budget of the recurrent nets (issue 13).** The paper trains its recurrent nets with one set of
  settings (Table 2); quick caps an epoch at 40 batches (about a sixth of a pass over the training windows) and
  gives the GRU and the LSTM the same capped budget (40 epochs, patience 10, Adam step 3e-3). With its former
  budget (25 capped epochs, patience 8, step 1e-3) the GRU stopped after little more than one pass over the data,
  its best epoch early and its training loss still falling: under-trained, which is why it trailed the static MLP.
  Early stopping then watches 4 validation episodes, a noisy signal, so which of GRU and LSTM ends ahead moves
  with the seed (and even with float-level differences between machines); the order is judged on the mean over
  seeds (the quick runs of seeds 0, 1 and 2 are in bench/results/experiments).
- **Table 4 needs more episodes per frequency.** The 20 % test share of the quick dataset holds 1-2 episodes per
  frequency, too few for a trend, so a separate test-only dataset (4 episodes at each frequency, new seeds,
  never trained on) gives Table 4 a second column set. Part of the rise at 2 Hz is the paper's own caveat
  (sect. 3.3): 50 samples per cycle, the window spans a full cycle.
- **Sizes the paper leaves open** (MLP 64-64 ReLU, GRU 64 units, polynomial without cross terms) are estimates,
  marked in `learn/models/`.
"""

"""Pieces every experiment uses: evaluation on held-out episodes, latency, markdown tables."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from collections.abc import Sequence as Seq
from pathlib import Path
from typing import Any

import numpy as np
import torch

from learn import metrics as M
from learn.data import Sequence
from learn.models.base import Compensator
from learn.train import single_thread  # re-exported: the experiments' entry points use it

HISTORY_CURVES = ("train_loss", "valid_loss")  # per-epoch curves: "loss_curve", not "training"

__all__ = ["batch_latency", "evaluate", "fit_model", "fmt", "make_data", "md_table", "select_mode", "single_thread", "streaming_latency"]


def make_data(data_dir, cfg, log: Callable[[str], None]):
    """Generate the dataset of `cfg` into data_dir, or reuse the shards already there (same config)."""
    from pathlib import Path

    from sensors.warp_setup import init_warp
    from simulate.generation.run import generate

    init_warp()
    t0 = time.perf_counter()
    generate(cfg, data_dir)
    log(f"data: {data_dir} ({cfg.generation.episodes} episodes, {time.perf_counter() - t0:.1f} s incl. reuse)")
    return Path(data_dir)


def select_mode(modes: dict[str, Any], mode: str, models: Seq[str] | None, known: Seq[str] | None = None) -> Any:
    """The experiment's Mode for `mode`, after checking that every requested model is one it knows
    (ValueError naming the allowed values otherwise). known: the mode's model names (default mode.models)."""
    if mode not in modes:
        raise ValueError(f"mode must be one of {sorted(modes)}, got {mode!r}")
    md = modes[mode]
    names = list(md.models if known is None else known)
    unknown = [k for k in (models or []) if k not in names]
    if unknown:
        raise ValueError(f"unknown model(s) {unknown}; known: {sorted(names)}")
    return md


def evaluate(comp: Compensator, seqs: Seq[Sequence], drive: str | None = None) -> dict[str, Any]:
    """Point metrics over all samples of ``seqs`` and, with a drive channel, the hysteresis error of
    each cycle (% FSO): 'hyst_mean' (mean over cycles) and 'hyst_worst'."""
    preds = [comp.predict(s.x) for s in seqs]
    ref = np.concatenate([s.y[:, 0] for s in seqs])
    est = np.concatenate([p[:, 0] for p in preds])
    out: dict[str, Any] = M.regression_metrics(ref, est)
    out["n_samples"] = len(ref)
    if drive is not None:
        cyc = [h for s, p in zip(seqs, preds) for h in M.loop_hysteresis(s.y[:, 0], p[:, 0], s.extra[drive])]
        cyc = [h for h in cyc if np.isfinite(h)]
        out["hyst_mean"] = float(np.mean(cyc)) if cyc else float("nan")
        out["hyst_worst"] = float(np.max(cyc)) if cyc else float("nan")
        out["n_cycles"] = len(cyc)
    return out


def raw_hysteresis(seqs: Seq[Sequence], drive: str) -> dict[str, float]:
    """Hysteresis error of the uncompensated sensor (force vs its first input channel)."""
    cyc = [h for s in seqs for h in M.loop_hysteresis(s.y[:, 0], s.x[:, 0], s.extra[drive])]
    cyc = [h for h in cyc if np.isfinite(h)]
    return {"hyst_mean": float(np.mean(cyc)) if cyc else float("nan"),
            "hyst_worst": float(np.max(cyc)) if cyc else float("nan"), "n_cycles": len(cyc)}


def fit_model(
    kind: str,
    hparams: dict[str, Any],
    xs: Seq[np.ndarray],
    ys: Seq[np.ndarray],
    valid: tuple[Seq[np.ndarray], Seq[np.ndarray]] | None,
    *,
    seed: int,
    progress: bool = False,
    fit_kw: dict[str, Any] | None = None,
    assess: Callable[[Compensator], dict[str, Any]] | None = None,
    latency_x: np.ndarray | None = None,
    latency_n: int = 300,
    history_skip: Seq[str] = (),
    checkpoint: Path | None = None,
    dataset: Any = None,
    checkpoint_extra: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
) -> tuple[Compensator, dict[str, Any]]:
    """The experiments' "train one model, evaluate, time, checkpoint" step.

    make_model(kind, **hparams).fit(xs, ys, valid, seed, progress, **fit_kw) (inputs / targets / units go in
    fit_kw), then a record: what ``assess(comp)`` returns (the experiment's own metrics, in its order),
    "fit_seconds", "hparams", "training" (the history without its per-epoch curves and ``history_skip``),
    "loss_curve" (train / valid per epoch), and with ``latency_x`` "latency" (streaming_latency over
    ``latency_n`` samples). With ``checkpoint`` the model is saved there (``dataset`` hash, extra =
    ``checkpoint_extra(record)``). Returns (fitted model, record)."""
    from learn.checkpoint import save_checkpoint
    from learn.models import make_model

    comp = make_model(kind, **hparams)
    t0 = time.perf_counter()
    comp.fit(xs, ys, valid=valid, seed=seed, progress=progress, **(fit_kw or {}))
    rec: dict[str, Any] = {"fit_seconds": time.perf_counter() - t0}
    if assess is not None:
        rec = {**assess(comp), **rec}
    skip = set(HISTORY_CURVES) | set(history_skip)
    rec["hparams"] = comp.hparams
    rec["training"] = {k: v for k, v in comp.history.items() if k not in skip}
    rec["loss_curve"] = {"train": comp.history.get("train_loss", []), "valid": comp.history.get("valid_loss", [])}
    if latency_x is not None:
        rec["latency"] = streaming_latency(comp, latency_x, n=latency_n)
    if checkpoint is not None:
        save_checkpoint(comp, checkpoint, dataset=dataset, extra=checkpoint_extra(rec) if checkpoint_extra else None)
    return comp, rec


def streaming_latency(comp: Compensator, x: np.ndarray, n: int = 300, warmup: int = 20, threads: int = 1) -> dict[str, float]:
    """Per-sample latency of comp.stream() on one CPU thread (median and mean, ms), and the largest
    difference between the streamed and the batch estimates on the same samples."""
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        x = np.asarray(x)[: n + warmup]
        st = comp.stream()
        ts, ys = [], []
        for v in x:
            t0 = time.perf_counter()
            ys.append(st.step(v))
            ts.append(time.perf_counter() - t0)
        ts = np.asarray(ts[warmup:]) * 1e3
        diff = float(np.max(np.abs(np.stack(ys) - comp.predict(x))))
        return {"median_ms": float(np.median(ts)), "mean_ms": float(ts.mean()), "p99_ms": float(np.percentile(ts, 99)),
                "n": len(ts), "threads": threads, "stream_vs_batch_max_abs": diff}
    finally:
        torch.set_num_threads(old)


def batch_latency(comp: Compensator, x: np.ndarray, threads: int = 1, repeat: int = 3) -> float:
    """Amortised batch inference time per sample (ms) over one episode, one thread."""
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        best = math.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            comp.predict(x)
            best = min(best, time.perf_counter() - t0)
        return 1e3 * best / len(x)
    finally:
        torch.set_num_threads(old)


def fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        if not math.isfinite(v):
            return "–"
        return f"{v:.{nd}f}"
    return str(v)


def md_table(header: Seq[str], rows: Seq[Seq[Any]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)

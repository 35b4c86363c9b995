"""Pre-training on simulated data and the fine-tuning report (`piezotwin pretrain`, `piezotwin finetune`).

``pretrain`` trains a compensator on a generated dataset with the input map of learn.finetune (ln of
the resistance channel) and records that map in the checkpoint (``extra.input_map``: channel,
transform, sample rate). ``run_finetune`` compares, on the same held-out real runs:
  zero-shot            the checkpoint as is (simulator's input statistics on the mapped real input)
  zero-shot, restd.    the same net with the input z-score re-estimated from the real fine-tuning
                       runs' inputs (no labels)
  fine-tuned           learn.finetune.finetune (freeze policy, small lr, early stopping on real runs)
  from scratch         the same architecture trained on the real fine-tuning runs only
and a learning curve (test RMSE vs number of real training runs) for fine-tuned and from scratch;
writes report.md, metrics.json, learning_curve.png, predictions.png and checkpoints/{finetuned,scratch}.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Sequence as Seq

import numpy as np

from learn import finetune as FT
from learn import metrics as M
from learn.data import Sequence, dumps, load_sequences
from learn.experiments.common import fmt, md_table

__all__ = ["pretrain", "run_finetune", "checkpoint_input_map"]


def pretrain(data_dir: str | Path, out_dir: str | Path, *, kind: str = "tcn", hparams: dict[str, Any] | None = None,
             input_channel: str = "resistance_measured", target: str = "force", transform: str = "log",
             seed: int = 0, progress: bool = False) -> dict[str, Any]:
    """Train ``kind`` on a simulated dataset (input ln(channel) by default), save the checkpoint in out_dir."""
    from learn.checkpoint import save_checkpoint
    from learn.data import dataset_fingerprint
    from learn.models.base import make_model
    from sensors.data.manifest import shard_files
    from sensors.data.recording import Recording

    seqs = FT.apply_map(load_sequences(data_dir, [input_channel], [target]), transform)
    if len(seqs) < 3:
        raise ValueError(f"{data_dir}: needs at least 3 episodes to pre-train (has {len(seqs)})")
    with Recording(shard_files(data_dir)[0]) as rec:
        rate = rec.sensor_attrs.get("sample_rate_hz")
    rate = float(rate) if rate is not None else None
    sp = _split(seqs, seed)
    comp = make_model(kind, **(hparams or {}))
    t0 = time.perf_counter()
    comp.fit([s.x for s in sp["train"]], [s.y for s in sp["train"]],
             valid=([s.x for s in sp["valid"]], [s.y for s in sp["valid"]]), seed=seed, progress=progress,
             inputs=[input_channel], targets=[target], units=seqs[0].units)
    secs = time.perf_counter() - t0
    sim_rmse = FT.rmse_on(comp, sp["valid"])
    imap = {"channel": input_channel, "transform": transform, "rate_hz": rate}
    save_checkpoint(comp, out_dir, dataset=dataset_fingerprint(data_dir),
                    extra={"input_map": imap, "sim_valid_rmse": sim_rmse,
                           "split": {k: [s.key for s in v] for k, v in sp.items()}})
    return {"checkpoint": str(out_dir), "sim_valid_rmse": sim_rmse, "seconds": secs, "input_map": imap,
            "n_train": len(sp["train"]), "n_valid": len(sp["valid"])}


def _split(seqs: Seq[Sequence], seed: int) -> dict[str, list[Sequence]]:
    rng = np.random.default_rng(seed)
    perm = [seqs[i] for i in rng.permutation(len(seqs))]
    nv = max(1, len(seqs) // 5)
    return {"train": perm[nv:], "valid": perm[:nv]}


def checkpoint_input_map(cfg: dict[str, Any]) -> dict[str, Any]:
    """The input map a checkpoint was trained with (extra.input_map); older checkpoints: identity, no resampling."""
    im = dict((cfg.get("extra") or {}).get("input_map") or {})
    im.setdefault("channel", cfg["inputs"][0]["name"])
    im.setdefault("transform", "none")
    im.setdefault("rate_hz", None)
    return im


def _curve_sizes(n: int) -> list[int]:
    sizes = sorted({k for k in (1, 2, 4, 8, 16, 32) if k < n} | {n})
    return sizes


def run_finetune(checkpoint: str | Path, recording: str | Path, out_dir: str | Path, *,
                 train_fraction: float | None = None, test_glob: str | None = None, policy: str = "head",
                 lr: float = 3e-4, max_epochs: int = 300, patience: int = 30, scratch_epochs: int = 300,
                 input_channel: str = "sensor", target: str = "force", transform: str | None = None,
                 rate_hz: float | None = None, curve: bool = True, compare_policies: bool = True, seed: int = 0,
                 progress: bool = False, log: Callable[[str], None] = lambda s: None) -> dict[str, Any]:
    from learn.checkpoint import load_checkpoint, read_config, save_checkpoint

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = read_config(checkpoint)
    base = load_checkpoint(checkpoint)
    FT._torch_only(base)
    im = checkpoint_input_map(cfg)
    transform = transform or im["transform"]
    rate = rate_hz or im["rate_hz"]
    imap = FT.InputMap(transform, rate)
    raw = FT.load_recording(recording, [input_channel], [target], rate_hz=rate)
    seqs = FT.apply_map(raw, transform)
    if base.n_in != seqs[0].x.shape[1]:
        raise ValueError(f"checkpoint takes {base.n_in} input channel(s); '{input_channel}' has {seqs[0].x.shape[1]}")
    sp = FT.split_runs(seqs, train_fraction=train_fraction, test_glob=test_glob, seed=seed)
    log(f"real runs: {len(sp.train)} train, {len(sp.valid)} valid (early stopping), {len(sp.test)} test; input map: {imap.describe()}")

    def score(comp) -> dict[str, Any]:
        ref = np.concatenate([s.y[:, 0] for s in sp.test])
        est = np.concatenate([comp.predict(s.x)[:, 0] for s in sp.test])
        m = M.regression_metrics(ref, est)
        m["per_run_rmse"] = {s.key: M.rmse(s.y[:, 0], comp.predict(s.x)[:, 0]) for s in sp.test}
        return m

    t0 = time.perf_counter()
    results: dict[str, Any] = {}
    results["zero_shot"] = score(base)
    results["zero_shot_restandardised"] = score(FT.restandardise(base, sp.train))
    ft, ft_info = FT.finetune(base, sp.train, sp.valid, policy=policy, lr=lr, max_epochs=max_epochs,
                              patience=patience, seed=seed, progress=progress)
    results["finetuned"] = score(ft)
    log(f"fine-tuned ({policy}): {ft_info['epochs']} epochs, best {ft_info['best_epoch']}, test RMSE {results['finetuned']['rmse']:.3f} N")
    other = None
    if compare_policies:
        other = "none" if policy == "head" else "head"
        ft2, ft2_info = FT.finetune(base, sp.train, sp.valid, policy=other, lr=lr, max_epochs=max_epochs,
                                    patience=patience, seed=seed, progress=progress)
        results[f"finetuned_{other}"] = score(ft2)
    scratch = FT.train_from_scratch(base.kind, base.hparams, sp.train, sp.valid, seed=seed, progress=progress,
                                    max_epochs=scratch_epochs)
    results["scratch"] = score(scratch)
    log(f"from scratch: test RMSE {results['scratch']['rmse']:.3f} N")
    save_checkpoint(ft, out / "checkpoints" / "finetuned",
                    extra={"input_map": {"channel": input_channel, "transform": transform, "rate_hz": rate},
                           "finetuned_from": str(checkpoint), "freeze_policy": policy,
                           "split": sp.keys(), "test_metrics": results["finetuned"]})
    save_checkpoint(scratch, out / "checkpoints" / "scratch",
                    extra={"input_map": {"channel": input_channel, "transform": transform, "rate_hz": rate},
                           "split": sp.keys(), "test_metrics": results["scratch"]})

    lc: list[dict[str, Any]] = []
    if curve:
        by_key = {s.key: s for s in sp.train}
        for k in _curve_sizes(len(sp.train)):
            tr = [by_key[key] for key in sp.order[:k]]
            if k == len(sp.train):
                r_ft, r_sc = results["finetuned"]["rmse"], results["scratch"]["rmse"]
                r_zr = results["zero_shot_restandardised"]["rmse"]
            else:
                c_ft, _ = FT.finetune(base, tr, sp.valid, policy=policy, lr=lr, max_epochs=max_epochs, patience=patience, seed=seed)
                c_sc = FT.train_from_scratch(base.kind, base.hparams, tr, sp.valid, seed=seed, max_epochs=scratch_epochs)
                r_ft, r_sc = score(c_ft)["rmse"], score(c_sc)["rmse"]
                r_zr = score(FT.restandardise(base, tr))["rmse"]
            n_samp = int(sum(len(s) for s in tr))
            lc.append({"n_runs": k, "n_samples": n_samp, "seconds_of_data": n_samp / rate if rate else None,
                       "runs": [s.key for s in tr], "finetuned_rmse": r_ft, "scratch_rmse": r_sc,
                       "zero_shot_restandardised_rmse": r_zr})
            log(f"  curve {k} run(s): fine-tuned {r_ft:.3f} N, from scratch {r_sc:.3f} N")
    secs = time.perf_counter() - t0

    metrics = {
        "checkpoint": str(checkpoint), "recording": str(recording), "model": base.kind,
        "input_map": {"channel": input_channel, "simulated_channel": im["channel"], "transform": transform,
                      "rate_hz": rate, "normalisation": "z-score pooled over the real fine-tuning runs (not per recording)",
                      "description": imap.describe()},
        "freeze_policy": policy, "finetune": {k: v for k, v in ft_info.items() if k not in ("train_loss", "valid_loss")},
        "split": sp.keys(), "results": results, "learning_curve": lc, "seconds": secs, "seed": seed,
        "test_force_range_n": [float(min(s.y.min() for s in sp.test)), float(max(s.y.max() for s in sp.test))],
    }
    (out / "metrics.json").write_text(dumps(metrics))
    _plots(out, base, ft, scratch, sp, lc, rate)
    _report(out, metrics, other)
    return metrics


def _plots(out: Path, base, ft, scratch, sp, lc, rate) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if lc:
        fig, ax = plt.subplots(figsize=(5, 3.5))
        n = [r["n_runs"] for r in lc]
        ax.plot(n, [r["finetuned_rmse"] for r in lc], "o-", label="fine-tuned")
        ax.plot(n, [r["scratch_rmse"] for r in lc], "s-", label="from scratch")
        ax.plot(n, [r["zero_shot_restandardised_rmse"] for r in lc], "^--", label="zero-shot (restandardised)")
        ax.set_xlabel("real training runs")
        ax.set_ylabel("test force RMSE (N)")
        ax.set_xticks(n)
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "learning_curve.png", dpi=120)
        plt.close(fig)
    s = max(sp.test, key=lambda q: float(q.y.max()))
    t = s.extra.get("time", np.arange(len(s)) / (rate or 1.0))
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.plot(t, s.y[:, 0], "k", lw=1.2, label="load cell")
    for comp, lab in ((FT.restandardise(base, sp.train), "zero-shot (restd.)"), (ft, "fine-tuned"), (scratch, "from scratch")):
        ax.plot(t, comp.predict(s.x)[:, 0], lw=0.9, label=lab)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)")
    ax.set_title(f"test run {s.key}")
    ax.legend(fontsize=8, ncol=4)
    fig.tight_layout()
    fig.savefig(out / "predictions.png", dpi=120)
    plt.close(fig)


def _report(out: Path, m: dict[str, Any], other: str | None) -> None:
    r = m["results"]
    rows = [["zero-shot (simulator's input statistics)", *(fmt(r["zero_shot"][k]) for k in ("rmse", "mae", "r2"))],
            ["zero-shot, input restandardised on real runs (no labels)", *(fmt(r["zero_shot_restandardised"][k]) for k in ("rmse", "mae", "r2"))],
            [f"**fine-tuned** (freeze policy `{m['freeze_policy']}`)", *(fmt(r["finetuned"][k]) for k in ("rmse", "mae", "r2"))]]
    if other:
        rows.append([f"fine-tuned, policy `{other}` (ablation)", *(fmt(r[f'finetuned_{other}'][k]) for k in ("rmse", "mae", "r2"))])
    rows.append(["from scratch (real runs only)", *(fmt(r["scratch"][k]) for k in ("rmse", "mae", "r2"))])
    f = m["finetune"]
    sp = m["split"]
    lines = [
        "# Fine-tuning on a real recording", "",
        f"Checkpoint `{m['checkpoint']}` ({m['model']}), recording `{m['recording']}`.", "",
        "## Input mapping", "",
        f"Real channel `{m['input_map']['channel']}` <-> simulated `{m['input_map']['simulated_channel']}`: "
        f"{m['input_map']['description']}; then {m['input_map']['normalisation']}.", "",
        "## Split (whole runs)", "",
        f"- train ({len(sp['train'])}): {', '.join(sp['train'])}",
        f"- valid, early stopping ({len(sp['valid'])}): {', '.join(sp['valid'])}",
        f"- test ({len(sp['test'])}): {', '.join(sp['test'])}", "",
        "## Freeze policy", "",
        f"`{m['freeze_policy']}`: trained {', '.join(f['trained'])} ({f['n_trainable']} of {f['n_parameters']} parameters); "
        f"frozen: {', '.join(f['frozen']) or 'nothing'}. Adam lr {f['lr']:g}, early stopping on the valid runs "
        f"({f['epochs']} epochs, best {f['best_epoch']}).", "",
        "## Test force error (same real test runs)", "",
        md_table(["model", "RMSE (N)", "MAE (N)", "R^2"], rows), "",
        f"Test force range {m['test_force_range_n'][0]:.2f} .. {m['test_force_range_n'][1]:.2f} N.", "",
    ]
    if m["learning_curve"]:
        lines += ["## Learning curve (test RMSE vs real training runs)", "",
                  md_table(["runs", "samples", "fine-tuned (N)", "from scratch (N)", "zero-shot restd. (N)"],
                           [[c["n_runs"], c["n_samples"], fmt(c["finetuned_rmse"]), fmt(c["scratch_rmse"]),
                             fmt(c["zero_shot_restandardised_rmse"])] for c in m["learning_curve"]]), "",
                  "![learning curve](learning_curve.png)", ""]
    lines += ["![predictions](predictions.png)", "", f"Total {m['seconds']:.0f} s. Numbers in metrics.json."]
    (out / "report.md").write_text("\n".join(lines) + "\n")

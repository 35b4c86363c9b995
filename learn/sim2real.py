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
from collections.abc import Callable
from collections.abc import Sequence as Seq
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from learn import finetune as FT
from learn import metrics as M
from learn.data import Sequence, dumps, load_sequences
from learn.experiments.common import fmt, md_table
from learn.train import single_thread

__all__ = ["checkpoint_input_map", "pretrain", "run_finetune"]


@single_thread
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


@single_thread
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


# ---------------------------------------------------------------------------------------------- the whole loop

S2R_BUDGET = {  # the default budget of `piezotwin sim2real` (2 CPU cores, <= 15 min on the Lupasic logs)
    "fit_rate_hz": 20.0, "n_boot": 16, "n_episodes": 96, "episode_s": 60.0, "pretrain_epochs": 40,
    "pretrain_patience": 12, "finetune_epochs": 120, "finetune_patience": 20, "lr": 2e-3, "policy": "none",
    "finetune_norm": "checkpoint", "rehearsal": 0.0, "n_train_seeds": 3, "time_budget_s": 900.0, "valid_tail": 0.25,
    "press_slope": False, "rated_force_n": None, "run_level": False, "fit_threshold": False,
    "creep_linear": False, "finetune_method": ["plain", "shrink_perturb"], "l2sp_alpha": 0.1, "l2sp_beta": 0.01, "pipeline_seed": 0,
    "fit_contact": False, "tail_by": "presses", "static_blend": False, "fit_tunnel": False, "latency": False,
    "two_point_level": "shrunk",
}
TWO_POINT_LEVELS = ("measured", "shrunk")
# two_point_level: how the two-point calibration's known load sets the film level of the presses to come
# (two_point_calibration): "measured" (the calibration press's own level, in full) or "shrunk" (the run level's
# posterior mean under the fitted levels model, k x that level, k = s_run^2 / (s_run^2 + s_w^2):
# run_level_shrinkage); round 15 (session 26), adopted by the rule written before scoring
# (bench/results/s2r-two-point-shrink-rule.md): over the five recorded splits the two-point RMSE went 16.0 -> 14.7 % of
# full scale on the mean, no split rising more than 5.4 % (bench/bench_s2r_two_point_shrink.py, s2r-two-point-shrink.json)
# latency: the rig's label latency read from the training runs and lined up in the fit (sensors.chain_fit, "Label
# latency"), the generated labels delayed by it; round 13 (session 22), scored by the rule in
# bench/bench_s2r_latency.py written before scoring: not adopted (the Lupasic fits get worse)
# fit_tunnel: the chain's tunneling term (R_film x exp(-F_e / F_t), sensors.chain_fit, Zhang et al. 2000) with F_t
# fitted; round 12 (session 21), scored by the rule in bench/bench_s2r_tunnel.py written before scoring
# tail_by: how learn.finetune.split_tail cuts each training run's validation tail: "presses" (round 11, adopted on its
# definition: the last quarter of the run's loaded presses, peak >= 10 % of the full scale) or "samples" (rounds 4-10:
# the last quarter of its samples, which gave a 1 N run a tail of one 0.2 N press)
# static_blend: the fine-tuned net as a residual on the static calibration curve, F = S(x) + w (N - S(x)) (S fitted on
# the budget's heads, w in [0, 1] by least squares on its validation tails; StaticBlend); round 11's candidate, adopted
# only by the rule written before scoring (CHANGELOG): held-out second halves of the tails, blend - net over pipeline
# seeds 0-2, -0.207 +- 0.066 N (pike1 -> pike2) and +0.009 +- 0.006 N (pike2 -> pike1): not adopted
# (bench/results/s2r-blend-*.json). Off: the net alone, as before; its diagnostics are recorded per fit either way
# fit_contact: the chain's contact-area term (the tip's contact share s = (F / (F + F_a))^(2/3), R_film / s;
# sensors.chain_fit.contact_fraction) with F_a fitted; ninth round, scored by the rule written before scoring
# (CHANGELOG): validation-tail paired difference over pipeline seeds 0-2 -0.003 +- 0.041 N (pike1 -> pike2) and
# +0.011 +- 0.030 N (pike2 -> pike1), not adopted (bench/results/s2r-contact-*.json). Off: F_a = 0, rounds 1-8 bit for bit
# finetune_method: plain | l2sp | lpft | shrink_perturb (learn.finetune; L2-SP's alpha / beta: learn.finetune.L2SP_ALPHA, an estimate);
# eighth round, adopted only by the rule written before scoring (CHANGELOG). A list is a grid (finetune_methods): each
# fine-tunes per budget and seed, the lowest validation loss on the tails kept. [plain, shrink_perturb] (the warm start
# chosen by the data: shrink-and-perturb where the pre-trained net fits the real runs poorly) adopted in round 16
# (session 26) by the rule written before scoring (bench/results/s2r-method-select-rule.md, s2r-method-select.json:
# pike1 -> pike2 3.93 -> 2.36 N with all runs, no budget of the five splits worse; plain, round 1-15, alone before)
# pipeline_seed: varies the generation draw and the pre-training (its simulated split, init and batch order) with the
# fit, the learning curve's run order and the fine-tuning / scratch seeds held: root seed + 100 x pipeline_seed for
# steps 2-3 (0: the recorded runs); measures the pipeline's spread (bench/bench_s2r_pipeline_noise.py)
# creep_linear: the chain's creep force proportional to the load (linear creep; F_c held at its bound;
# sensors.chain_fit.fit_chain), seventh round, adopted only by the rule written before scoring (CHANGELOG)
# fit_threshold: fit the chain's threshold force F_0 (F_eff = F - F_0, the force the curved mount carries before the
# film is loaded; sensors.chain_fit.fit_chain) on a board whose readout shows no floor (the Lupasic board); seventh
# round, adopted only by the rule written before scoring (CHANGELOG)
# run_level: each simulated run's ln gain from the hierarchical run-level sd of the fitted press levels
# (sensors.chain_fit.run_level_sd) instead of the std of the run means; sixth round, adopted only by the
# validation-tail rule (CHANGELOG)
# rated_force_n (N): the sensor's / rig's rated force, set by the user (`sim2real --rated-force-n`); the simulated
# presses then span it (chain_fit.peak_force_dist). None: the training presses' own range (rounds 1-4). Not the
# default of the recorded runs: with 40 N (the README's 10-40 N) pike2 -> pike1's fine-tuned RMSE on the training
# runs' validation tails rose 0.51 -> 0.73 N (rule fixed before scoring; pike1 -> pike2: the rating lies inside its
# training presses, the same run; bench/results/s2r-rated-range-*.json, CHANGELOG fifth round).
# valid_tail: the share of each training run (its last presses) that stops fine-tuning and scratch early (round 4;
# before, whole runs of the pool did, which for the TAMS covers was another cover and for pike2 the only other run)
# rehearsal 0: the grid [0, 1] chosen on the real valid runs picked 0 at every budget of both Lupasic directions
# (results of 2026-11-24) and doubled the fine-tuning time; `--budget`-style overrides can still pass a grid.
# n_train_seeds: fine-tuned and scratch each averaged over the same 3 training seeds (fixed before any test score).
# lr 2e-3: the TCN's own (scratch's) Adam rate, so fine-tuned and scratch get the same rate, epochs and early
# stopping; at 3e-4 the fine-tuning stopped on the valid runs (best epochs ~20) with the pre-trained net's 2x
# over-prediction (bench/results/s2r-diagnosis-*.json) only partly unlearned.
FINETUNE_KEYS = ("finetune_epochs", "finetune_patience", "lr", "policy", "finetune_norm", "rehearsal", "n_train_seeds",
                 "time_budget_s", "valid_tail", "finetune_method", "l2sp_alpha", "l2sp_beta", "tail_by", "static_blend",
                 "two_point_level")


def pipeline_seed(seed: int, B: dict) -> int:
    """The seed of steps 2-3 (generation, pre-training): the root seed, moved by 100 per pipeline seed."""
    return int(seed) + 100 * int(B.get("pipeline_seed") or 0)


def generate_step(p, rand, gen_f: Path, B: dict, seed: int, progress: Callable[[int], None] | None = None) -> None:
    """Step 2: the randomized simulated episodes around the fitted chain ``p``."""
    from simulate.generation.chain_gen import generate_chain

    generate_chain(p, rand, gen_f, n_episodes=int(B["n_episodes"]), root_seed=pipeline_seed(seed, B),
                   duration_s=float(B["episode_s"]), rate_hz=float(B["fit_rate_hz"]), progress=progress)


def reread_through(seq: Sequence, p) -> Sequence:
    """A real run read through another reference resistor than the chain's (its ``reference_resistor_ohm``), re-read
    as through the chain's: R through the run's own divider, then the chain's divider (sensors.chain_fit: the
    resistor is told, nothing is fitted); its readout floor and ceiling stay where the run reached them. Other runs
    come back as they are."""
    from dataclasses import replace as _r

    from sensors.chain_fit import reading_from_resistance, resistance_from_reading

    r_ref = seq.meta.get("reference_resistor_ohm")
    if not r_ref or float(r_ref) == p.r_ref_ohm:
        return seq
    y = seq.x[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        r = resistance_from_reading(y, _r(p, r_ref_ohm=float(r_ref)))
        y2 = np.where(np.isfinite(r), reading_from_resistance(r, p), np.where(y - p.offset >= p.full_scale / 2,
                                                                               p.offset + p.full_scale, p.offset))
    x = seq.x.copy()
    x[:, 0] = y2
    meta = {**seq.meta, "reread_from_reference_resistor_ohm": float(r_ref), "reference_resistor_ohm": p.r_ref_ohm}
    return Sequence(x, seq.y, seq.inputs, seq.targets, seq.units, meta, seq.extra)


def input_transform(p) -> str:
    """The model's input map for the chain ``p``: x = ln(reading) where the reading falls with force (a "high"
    divider: reading ~ R / (R + r_ref)); x = ln(FS - reading) where it rises toward its full scale (a "low" divider:
    FS - reading ~ R / (R + r_ref), the same form), so either way x follows ln R (learn.finetune.HEADROOM)."""
    return "log" if p.divider == "high" else f"{FT.HEADROOM}{p.offset + p.full_scale:.9g}"


def pretrain_step(gen_f: Path, ck: Path, model: str, B: dict, seed: int, progress: bool = False, p=None) -> dict[str, Any]:
    """Step 3: pre-train ``model`` on the simulated episodes; writes the checkpoint ``ck`` whole (tmp + rename).
    ``p``: the fitted chain, which sets the input map (input_transform; None: x = ln reading)."""
    from learn.checkpoint import save_checkpoint
    from learn.models.base import make_model

    s = pipeline_seed(seed, B)
    transform = input_transform(p) if p is not None else "log"
    seqs = FT.apply_map(FT.load_recording(gen_f, ["sensor"], ["force"]), transform)
    sp = _split(seqs, s)
    comp = make_model(model, max_epochs=int(B["pretrain_epochs"]), patience=int(B["pretrain_patience"]))
    t0 = time.perf_counter()
    comp.fit([q.x for q in sp["train"]], [q.y for q in sp["train"]], valid=([q.x for q in sp["valid"]], [q.y for q in sp["valid"]]),
             seed=s, progress=progress, inputs=["sensor"], targets=["force"], units=seqs[0].units)
    hist = getattr(comp, "history", {}) or {}
    sim_rmse = FT.rmse_on(comp, sp["valid"])
    tmp = ck.with_name(ck.name + ".tmp")
    save_checkpoint(comp, tmp, extra={"input_map": {"channel": "sensor", "transform": transform, "rate_hz": float(B["fit_rate_hz"])},
                                       "sim_valid_rmse": sim_rmse})
    if ck.exists():
        import shutil

        shutil.rmtree(ck)
    tmp.replace(ck)
    return {"sim_valid_rmse": sim_rmse, "seconds": time.perf_counter() - t0, "epochs": hist.get("epochs"),
            "best_epoch": hist.get("best_epoch")}


def isotonic(x: np.ndarray, y: np.ndarray, n_knots: int = 200, decreasing: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Force as a non-increasing (decreasing=False: non-decreasing) function of x = ln reading (pool-adjacent-
    violators on quantile bins); returns knots (x ascending, y) for np.interp."""
    if not decreasing:
        kx, ky = isotonic(-np.asarray(x), y, n_knots)
        return -kx[::-1], ky[::-1]
    o = np.argsort(x)
    x, y = x[o], y[o]
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n_knots + 1)))
    b = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    cnt = np.bincount(b, minlength=len(edges) - 1).astype(float)
    keep = cnt > 0
    xm = (np.bincount(b, x, len(edges) - 1)[keep] / cnt[keep])
    ym = (np.bincount(b, y, len(edges) - 1)[keep] / cnt[keep])
    w = cnt[keep]
    # PAV for a non-increasing fit
    vals, wts, lens = [], [], []
    for v, ww in zip(ym, w):
        vals.append(v); wts.append(ww); lens.append(1)
        while len(vals) > 1 and vals[-2] < vals[-1]:
            v2, w2, l2 = vals.pop(), wts.pop(), lens.pop()
            vals[-1] = (vals[-1] * wts[-1] + v2 * w2) / (wts[-1] + w2)
            wts[-1] += w2
            lens[-1] += l2
    yf = np.repeat(vals, lens)
    return xm, yf


class StaticCurve:
    """The baseline a user fits without a model: force = monotone (isotonic) function of ln reading."""

    kind = "static_curve"

    def __init__(self, seqs):
        x = np.concatenate([s.x[:, 0] for s in seqs])
        y = np.concatenate([s.y[:, 0] for s in seqs])
        # the curve's direction from the data: force falls with the reading (a "high" divider) unless the ranks of
        # reading and force rise together (the reference on the ADC side)
        rx, ry = np.argsort(np.argsort(x)), np.argsort(np.argsort(y))
        self.decreasing = not (len(x) > 2 and np.corrcoef(rx, ry)[0, 1] > 0)
        self.kx, self.ky = isotonic(x, y, decreasing=self.decreasing)

    def predict(self, x: np.ndarray) -> np.ndarray:
        return np.interp(x[:, 0], self.kx, self.ky)[:, None]


def static_oracle(test: Seq[Sequence]) -> dict[str, Any]:
    """Not a model: the static curve fitted on the test runs themselves and scored on them (in-sample). Isotonic least
    squares (to its quantile bins, `isotonic`), so no monotone memoryless map of the reading does markedly better on
    these runs: its error is what the spread of force at equal reading (press placement, creep, hysteresis) leaves
    to any static reading; a net with history can go below it. Returns rmse, mae (N) and per_run_rmse."""
    curve = StaticCurve(test)
    ref = np.concatenate([s.y[:, 0] for s in test])
    est = np.concatenate([curve.predict(s.x)[:, 0] for s in test])
    return {"rmse": M.rmse(ref, est), "mae": float(np.mean(np.abs(est - ref))),
            "per_run_rmse": {s.key: M.rmse(s.y[:, 0], curve.predict(s.x)[:, 0]) for s in test}}


def blend_weight(comp, static, seqs: Seq[Sequence]) -> float | None:
    """The least-squares weight w in [0, 1] of ``comp``'s correction to ``static`` on ``seqs`` (labelled): minimises
    sum (S + w (N - S) - F)^2, w = <N - S, F - S> / <N - S, N - S>, clipped (Breiman 1996, "Stacked regressions",
    Machine Learning 24: a non-negative combination of predictors weighted on held-out data). None without data."""
    if not seqs:
        return None
    n = np.concatenate([comp.predict(s.x)[:, 0] for s in seqs])
    st = np.concatenate([static.predict(s.x)[:, 0] for s in seqs])
    f = np.concatenate([s.y[:, 0] for s in seqs])
    d = n - st
    den = float(np.dot(d, d))
    return float(np.clip(np.dot(d, f - st) / den, 0.0, 1.0)) if den > 0.0 else 1.0


class StaticBlend:
    """A net as a residual on the static calibration curve: F = S(x) + w (N(x) - S(x)), S the monotone curve of
    force on ln reading fitted on the same sensor's training data (StaticCurve), N the fine-tuned net (its dynamics:
    creep, loading history), w its weight (blend_weight). w = 1: the net alone; w = 0: the curve alone."""

    kind = "static_blend"

    def __init__(self, comp, static, w: float):
        self.comp, self.static, self.w = comp, static, float(w)

    def predict(self, x: np.ndarray) -> np.ndarray:
        s = self.static.predict(x)
        return s + self.w * (self.comp.predict(x) - s)


class _Calibrated:
    """A compensator fed the two-point calibrated reading (see two_point_calibration)."""

    def __init__(self, comp, cal: TwoPoint):
        self.comp, self.cal = comp, cal

    def predict(self, x: np.ndarray) -> np.ndarray:
        return self.comp.predict(self.cal.apply(x))


@dataclass
class TwoPoint:
    """Two-point calibration of a new sensor's readout onto the identified chain: point 1, the unloaded
    reading, is the readout's rest level (the full scale of a "high" divider without a leak: the board gain;
    an ADC of known full scale keeps it); point 2, one known load, is the film's level at that place (ln r0
    shift). x = ln reading -> inverse divider with the sensor's full scale -> film resistance (leak and series
    undone) / exp(level) -> the chain's readout -> ln."""

    p: Any  # sensors.chain_fit.ChainParams
    full_scale: float  # the new sensor's unloaded reading (minus the offset), reading units
    level_ln: float  # ln R_new - ln R_chain at the known load

    def apply(self, x: np.ndarray) -> np.ndarray:
        from sensors.chain_fit import reading_from_resistance, total_resistance

        p = self.p
        u = (FT.inverse_transform(x, input_transform(p)) - p.offset) / self.full_scale
        u = np.clip(u, 1e-9, 1.0 - 1e-6) if p.divider == "high" else np.clip(u, 1e-6, 1.0 - 1e-9)
        r = p.r_ref_ohm * (u / (1 - u) if p.divider == "high" else (1 - u) / u)
        film = film_of_total(r, p)
        return FT.forward_transform(reading_from_resistance(total_resistance(film * np.exp(-self.level_ln), p), p),
                                    input_transform(p))


def film_of_total(r: np.ndarray, p) -> np.ndarray:
    """The film's resistance (ohm) under a total divider resistance r: the leak in parallel and the series
    resistance undone (inf where r reaches the leak: the film is open)."""
    L = p.r_leak_ohm
    with np.errstate(divide="ignore", invalid="ignore"):
        rr = np.where(r < 0.999 * L, r * L / (L - r), np.inf)
    return np.maximum(rr - p.r_series_ohm, 1e-3 * np.minimum(rr, 1e30))


def run_level_shrinkage(p, fit_json: dict[str, Any] | None) -> float:
    """k = s_run^2 / (s_run^2 + s_w^2): the share of one press's level (l = mu + u_run + e_press, sensors.chain_fit)
    that is its run's, so k (l_1 - mu) is the best linear unbiased predictor of the run level of the presses to come
    given that press (the random-effects posterior mean; Robinson, Statist. Sci. 6, 1991). s_run: the fit's run-level
    sd (p.level_run_log_sd), s_w: its within-run sd (fit.json error.level_run_sd.within_run_sd). 1 where the fit
    has no within-run sd (every press then says all about its run)."""
    lr = ((fit_json or {}).get("error") or {}).get("level_run_sd") or {}
    sw, srun = lr.get("within_run_sd"), float(getattr(p, "level_run_log_sd", 0.0) or 0.0)
    if sw is None or not np.isfinite(sw) or sw <= 0:
        return 1.0
    return float(srun ** 2 / (srun ** 2 + float(sw) ** 2))


def two_point_calibration(p, run_seq, rate_hz: float, level_shrink: float = 1.0) -> tuple[TwoPoint, dict[str, Any]]:
    """Two-point calibration as a user does it on the sensor to be used (the first test run): the unloaded
    reading before its first press, and one known load (that press's plateau, the load cell's median over
    the samples >= 90 % of its peak). ``level_shrink`` (k in [0, 1], `run_level_shrinkage`): the share of that
    press's measured level applied to the presses to come (1: all of it). Returns the calibration and its record
    (``calibration_end_sample``: the samples up to the end of that press, left out of the scored test data)."""
    if not 0.0 <= level_shrink <= 1.0:
        raise ValueError(f"level_shrink must be in [0, 1] (got {level_shrink})")
    from dataclasses import replace as _r

    from sensors.chain_fit import presses_of, resistance_from_reading, simulate_reading

    f = run_seq.y[:, 0]
    y = FT.inverse_transform(run_seq.x[:, 0], input_transform(p))
    found = presses_of(f, max(0.1 * f.max(), 0.05))
    if not found:
        raise ValueError(f"test run {run_seq.meta.get('key', '?')}: no press above 0.05 N, and the two-point "
                         "calibration takes its known load from the first press")
    sl = found[0]
    rest = np.flatnonzero(f[: sl.start] < 0.02 * f.max())
    # point 1 gives the gain only where the rest level is the full scale (a "high" divider whose fit saw no leak:
    # the Lupasic board); an ADC divider of known full scale (TAMS) rests at its leak, and keeps its full scale
    y0 = float(np.median(y[rest] if len(rest) else y[f < 0.02 * f.max()]))
    fs = y0 - p.offset if p.divider == "high" and p.r_leak_ohm >= 1e11 else p.full_scale
    hold = sl.start + np.flatnonzero(f[sl] >= 0.9 * f[sl].max())
    q = _r(p, noise_sd=0.0, miss_prob=0.0)
    r_chain = film_of_total(resistance_from_reading(simulate_reading(f[: hold[-1] + 1], 1.0 / rate_hz, q), q)[hold], p)
    r_new = film_of_total(resistance_from_reading(y[hold], p, fs=fs), p)
    ok = np.isfinite(r_chain) & np.isfinite(r_new)
    measured = float(np.median(np.log(r_new[ok])) - np.median(np.log(r_chain[ok]))) if ok.any() else 0.0
    level = level_shrink * measured
    cal = TwoPoint(p, fs, level)
    return cal, {"calibration_run": run_seq.key, "unloaded_reading": y0, "chain_full_scale": p.full_scale,
                 "full_scale_used": fs, "known_load_n": float(np.median(f[hold])), "level_ln": level,
                 "level_ln_measured": measured, "level_shrink": float(level_shrink),
                 "calibration_end_sample": int(sl.stop)}


@single_thread
def run_sim2real(family: str, recording: str | Path, out_dir: str | Path, *, test_glob: str, budget: dict | None = None,
                 seed: int = 0, input_channel: str = "sensor", target: str = "force", model: str = "tcn",
                 progress: bool = False, log: Callable[[str], None] = lambda s: None,
                 command: str | None = None) -> dict[str, Any]:
    """fit -> randomized generation -> pre-training -> fine-tuning -> report; each step's artefact is written
    whole (tmp + rename) and skipped when present with the same step config (state.json). Torch trains on one
    thread (`single_thread`), so the numbers do not depend on the machine's core count."""
    import json

    from learn.checkpoint import load_checkpoint
    from scenes.randomize import Randomization
    from sensors.data.resample import key_matches
    from sensors import chain_fit as C

    B = {**S2R_BUDGET, **(budget or {})}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    state_f = out / "state.json"
    state = json.loads(state_f.read_text()) if state_f.is_file() else {}
    # the steps 1-3 key: the fine-tuning settings (step 4, always rerun) do not invalidate fit, data or pre-training
    key = {"family": family, "recording": str(Path(recording).resolve()), "test": test_glob,
           "budget": {k: v for k, v in B.items() if k not in FINETUNE_KEYS}, "seed": seed, "model": model,
           **({"channels": [input_channel, target]} if (input_channel, target) != ("sensor", "force") else {})}
    if state.get("key") != key:
        # the fit does not depend on the pipeline seed (steps 2-3 only): kept when nothing else changed
        same_fit = _fit_key(state.get("key")) == _fit_key(key) and "fit" in state.get("done", {})
        state = {"key": key, "done": {"fit": state["done"]["fit"]} if same_fit else {}}
    rate = float(B["fit_rate_hz"])
    t_all = time.perf_counter()

    clock = {"wall": time.perf_counter(), "cpu": cpu_seconds()}

    def mark(step, info):
        # wall and CPU seconds of the step (CPU: this process, all threads, and its finished child processes), for the stated time budget
        w, c = time.perf_counter(), cpu_seconds()
        info = {**info, "wall_s": w - clock["wall"], "cpu_s": c - clock["cpu"]}
        clock.update(wall=w, cpu=c)
        state["done"][step] = info
        tmp = state_f.with_suffix(".tmp")
        tmp.write_text(dumps(state))
        tmp.replace(state_f)

    runs = C.load_real_runs(recording, input_channel=input_channel, target=target, rate_hz=rate)
    train_runs = [r for r in runs if not key_matches(r.key, test_glob)]
    test_keys = [r.key for r in runs if key_matches(r.key, test_glob)]
    if not test_keys:
        raise ValueError(f"--test-episodes {test_glob!r} matches no episode of {recording}")
    if len(train_runs) < 2:
        raise ValueError(f"{recording}: needs at least 2 runs outside {test_glob!r} (one trains, one stops early)")

    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), disable=not progress, transient=False) as bar:
        # 1. fit
        fit_f = out / "fit.json"
        if "fit" not in state["done"] or not fit_f.is_file():
            task = bar.add_task("1/4 fit (bootstrap over presses)", total=B["n_boot"] + 1)
            p0 = _chain_prior(family, train_runs)  # the simulated sensor reads as the training runs do
            # placement-level prior where presses land at varying places (the Lupasic board: no ADC full scale)
            fit = C.fit_chain(train_runs, p0, n_boot=int(B["n_boot"]), seed=seed,
                              progress=lambda k, n: bar.update(task, completed=k), level_prior=not any(r.attrs.get("adc_full_scale") for r in runs),
                              fit_threshold=bool(B.get("fit_threshold")), creep_linear=bool(B.get("creep_linear")),
                              fit_contact=bool(B.get("fit_contact")), fit_tunnel=bool(B.get("fit_tunnel")),
                              latency=bool(B.get("latency")))
            held = C.evaluate(fit, [r for r in runs if r.key in test_keys])
            rand = C.randomization_from_fit(fit, train_runs, press_slope=bool(B["press_slope"]),
                                            rated_force_n=B.get("rated_force_n"), run_level=bool(B.get("run_level")))
            spread = C.press_slope_spread(fit, train_runs)  # measured whether drawn or not (reported)
            lead, lags = C.label_latency(train_runs)  # read whether lined up or not (reported; sensors.chain_fit)
            lag = {"reading_leads_label_s": lead, "lined_up": bool(B.get("latency")),
                   "run_lags_s": {r.key: v for r, v in zip(train_runs, lags)}}
            C.save_fit(fit, fit_f, {"family": family, "recording": str(recording), "fit_runs": [r.key for r in train_runs],
                                    "held_out": held, "randomization": rand.model_dump(mode="json"), "press_slope_spread": spread,
                                    "label_lag": lag})
            if lead > 0 and not B.get("latency"):
                log(f"fit: the reading leads its force label by {lead:.3f} s (median over the training runs); the labels "
                    "were not lined up (--latency does: see docs/real-sensors.md)")
            mark("fit", {"within_press_fit": fit.error["rms_log_reading_within_press"], "held_out": held,
                         "press_slope_spread": spread})
            log(f"fit: within-press rms ln reading {fit.error['rms_log_reading_within_press']:.3f} (fit runs), "
                f"{held.get('rms_log_reading_within_press', float('nan')):.3f} (held-out), levels in 90 % band "
                f"{held.get('level_in_band90', float('nan')):.2f}")
        p, fj = C.load_params(fit_f)
        rand = Randomization.model_validate(fj["randomization"])
        # 2. generate
        gen_f = out / "sim.h5"
        if "generate" not in state["done"] or not gen_f.is_file():
            task = bar.add_task("2/4 randomized generation", total=int(B["n_episodes"]))
            generate_step(p, rand, gen_f, B, seed, progress=lambda k: bar.update(task, completed=k))
            spread = simulated_press_spread(gen_f, train_runs, p)
            mark("generate", {"file": str(gen_f), "n_episodes": int(B["n_episodes"]), "press_spread": spread})
            if spread.get("ratio"):
                log(f"generated: presses read at equal force with ln sd {spread['sim_ln_reading_sd']:.3f} "
                    f"(real training presses {spread['real_ln_reading_sd']:.3f}, x{spread['ratio']:.2f})")
        # 3. pre-train
        ck = out / "checkpoints" / "pretrained"
        if "pretrain" not in state["done"] or not (ck / "config.json").is_file():
            task = bar.add_task("3/4 pre-training", total=1)
            info = pretrain_step(gen_f, ck, model, B, seed, progress=progress, p=p)
            bar.update(task, completed=1)
            mark("pretrain", info)
            log(f"pre-trained: simulated valid RMSE {info['sim_valid_rmse']:.3f} N, epochs {info['epochs']} (best {info['best_epoch']})")
        base = load_checkpoint(ck)
        # 4. fine-tune, baselines, learning curve
        task = bar.add_task("4/4 fine-tuning + baselines", total=1)
        sim = FT.apply_map(FT.load_recording(gen_f, ["sensor"], ["force"]), input_transform(p)) if max(_rehearsals(B)) > 0 else []
        m = _evaluate_loop(base, p, recording, test_glob, B, seed, input_channel, target, rate,
                           lambda k, n: bar.update(task, completed=k, total=n), log, sim=sim, fit_json=fj)
    w4, c4 = time.perf_counter() - clock["wall"], cpu_seconds() - clock["cpu"]
    m["steps"] = state["done"]
    m["budget"] = B
    m["command"] = command
    m["press_slope"] = {"measured": fj.get("press_slope_spread") or {},
                        "drawn": {k: rand.episode[k].value for k in ("slope_level_coef", "slope_press_sd") if k in rand.episode} or None}
    m["run_level"] = {"fit": {k: (fj.get("error") or {}).get(k) for k in ("level_run_sd", "level_band90_pooled_log")},
                      "level_run_sd_run_bootstrap_p5_p50_p95": (fj.get("ranges_p5_p50_p95") or {}).get("level_run_sd_run_bootstrap"),
                      "level_band90_log": fj.get("level_band90_log"), "episode_gain_log_sd": rand.episode["gain_log"].sd
                      if "gain_log" in rand.episode else None, "drawn_from_run_level_sd": bool(B.get("run_level"))}
    m["simulated_peak_force_n"] = {"low": rand.press["peak_force_n"].low, "high": rand.press["peak_force_n"].high,
                                   "rated_force_n": B.get("rated_force_n")} if "peak_force_n" in rand.press else None
    m["seconds_total_this_call"] = time.perf_counter() - t_all
    m["timing"] = _timing(state["done"], w4, c4, B)
    (out / "metrics.json").write_text(dumps(m))
    _s2r_report(out, m)
    return m


def simulated_press_spread(sim_file: Path, train_runs, p=None) -> dict[str, Any]:
    """sensors.chain_fit.press_spread of the simulated recording's presses against the real training runs', on the
    reading as the model reads it (input_transform of the chain ``p``: FS - reading where the reading rises)."""
    from sensors import chain_fit as C
    from sensors.data.recording import Recording

    t = input_transform(p) if p is not None else "log"
    as_read = lambda y: np.exp(FT.forward_transform(y, t))  # noqa: E731 - the reading the model's ln is taken of
    with Recording(sim_file) as rec:
        sim = [(rec.read(ep, "force"), as_read(rec.read(ep, "sensor")[:, 0])) for ep in rec.episode_ids]
    return C.press_spread([(r.force, as_read(r.reading)) for r in train_runs], sim)


def _fit_key(key: dict | None) -> Any:
    """The part of the steps 1-3 key the fit depends on (everything but the pipeline seed)."""
    if not key:
        return None
    return {**key, "budget": {k: v for k, v in key.get("budget", {}).items() if k != "pipeline_seed"}}


def _timing(done: dict[str, Any], wall4: float, cpu4: float, B: dict) -> dict[str, Any]:
    """The whole run's time: steps 1-3 as recorded when they ran (state.json) + step 4 of this call."""
    import os

    steps = {k: {"wall_s": done[k].get("wall_s"), "cpu_s": done[k].get("cpu_s")} for k in ("fit", "generate", "pretrain") if k in done}
    steps["finetune_and_baselines"] = {"wall_s": wall4, "cpu_s": cpu4}
    known = all(v["wall_s"] is not None for v in steps.values()) and len(steps) == 4
    wall = sum(v["wall_s"] for v in steps.values()) if known else None
    cpu = sum(v["cpu_s"] for v in steps.values()) if known else None
    return {"steps": steps, "wall_s": wall, "cpu_s": cpu, "budget_s": float(B["time_budget_s"]),
            "within_budget": (wall <= float(B["time_budget_s"])) if known else None,
            "torch_threads": int(__import__("torch").get_num_threads()), "cpu_count": os.cpu_count(),
            "load_average_at_end": list(os.getloadavg())}


def _chain_prior(family: str, runs) -> Any:
    from sensors.chain_fit import ChainParams, reading_direction

    adc = next((r.attrs.get("adc_full_scale") for r in runs if r.attrs.get("adc_full_scale")), None)
    rref = next((r.attrs.get("reference_resistor_ohm") for r in runs if r.attrs.get("reference_resistor_ohm")), None)
    p = ChainParams(divider=reading_direction(runs), r_ref_ohm=float(rref or 1e4), full_scale=float(adc or 1.0))
    if adc:  # an ADC divider (TAMS-like): a series floor and a cover threshold show
        p.r_series_ohm, p.threshold_force_n, p.exponent = 100.0, 0.05, 1.5  # estimate: starting point of the fit
    return p


def finetune_methods(B: dict) -> list[str]:
    """The budget's fine-tuning methods: one (str) or a grid (list), each tried per budget and training seed, the one
    of the lowest validation loss on the budget's tails kept (as the rehearsal share)."""
    m = B.get("finetune_method", "plain")
    ms = [str(x) for x in m] if isinstance(m, (list, tuple)) else [str(m)]
    bad = [x for x in ms if x not in FT.FINETUNE_METHODS]
    if not ms or bad:
        raise ValueError(f"finetune_method must be one or more of {', '.join(FT.FINETUNE_METHODS)} (got {m!r})")
    return ms


def cpu_seconds() -> float:
    """CPU seconds of this process (all threads) and of its finished child processes (step 4's `Trainings`)."""
    import resource

    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


TRAIN_WORKERS = 4  # at most this many processes for step 4's trainings (fewer where the machine has fewer cores)


def _train_job(job: tuple[str, tuple, dict[str, Any]]) -> Any:
    """One training of step 4 (a fine-tuning or a net from scratch), on one torch thread (`single_thread`: its numbers
    are then a function of the data and its seed alone, in whichever process it runs)."""
    what, args, kw = job
    return single_thread(FT.finetune if what == "finetune" else FT.train_from_scratch)(*args, **kw)


class Trainings:
    """Runs step 4's trainings side by side in up to `workers` spawned processes (None: min(TRAIN_WORKERS, cores);
    1: one after another here). Each training seeds itself and runs on one torch thread, so the nets are the same
    either way; the machine's cores only set how long it takes (the grid of warm starts doubled the fine-tuning)."""

    def __init__(self, workers: int | None = None):
        import os

        self.workers = max(1, min(TRAIN_WORKERS, os.cpu_count() or 1) if workers is None else int(workers))
        self.pool = None

    def run(self, jobs: list[tuple[str, tuple, dict[str, Any]]]) -> list[Any]:
        if self.workers == 1 or len(jobs) < 2:
            return [_train_job(j) for j in jobs]
        if self.pool is None:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            self.pool = ProcessPoolExecutor(self.workers, mp_context=mp.get_context("spawn"))
        return list(self.pool.map(_train_job, jobs))

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)
            self.pool = None

    def __enter__(self) -> Trainings:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _finetune_jobs(base, heads: Seq[Sequence], tails: Seq[Sequence], seed: int, B: dict, sim: Seq[Sequence] = (),
                   kw: dict[str, Any] | None = None) -> tuple[list[tuple[str, float]], list[tuple[str, tuple, dict]]]:
    """The fine-tunings of one budget and seed: every method (finetune_methods) x rehearsal share (the budget's
    grids), as (grid, jobs) for `Trainings.run`."""
    grid = [(mt, r) for mt in finetune_methods(B) for r in _rehearsals(B)]
    jobs = [("finetune", (base, heads, tails),
             {"rehearsal": rehearsal_set(sim, int(r * sum(len(s) for s in heads)), seed) if sim and r > 0 else [],
              "seed": seed, "method": mt, **(kw or {})}) for mt, r in grid]
    return grid, jobs


def _pick(grid: list[tuple[str, float]], results: list[tuple[Any, dict[str, Any]]]) -> tuple[Any, dict[str, Any], float, str]:
    """The fine-tuning of the lowest validation loss on the tails (ties: the first tried): (net, info, share, method)."""
    best = None
    for (mt, r), (c, ci) in zip(grid, results):
        if best is None or ci["best_loss"] < best[1]["best_loss"]:
            best = (c, ci, r, mt)
    return best


def best_finetune(base, heads: Seq[Sequence], tails: Seq[Sequence], seed: int, B: dict, sim: Seq[Sequence] = (),
                  kw: dict[str, Any] | None = None, trainings: Trainings | None = None) -> tuple[Any, dict[str, Any], float, str]:
    """Fine-tune ``base`` on ``heads`` for every method (finetune_methods) and rehearsal share (the budget's grids)
    and keep the one of the lowest validation loss on ``tails`` (never the test runs); ties keep the first tried.
    Returns (net, its info, rehearsal share, method)."""
    grid, jobs = _finetune_jobs(base, heads, tails, seed, B, sim, kw)
    return _pick(grid, (trainings or Trainings(1)).run(jobs))


def _rehearsals(B: dict) -> list[float]:
    r = B["rehearsal"]
    return [float(x) for x in r] if isinstance(r, (list, tuple)) else [float(r)]


def rehearsal_set(sim: Seq[Sequence], n_samples: int, seed: int) -> list[Sequence]:
    """Simulated episodes (a seeded random order) until they hold ``n_samples`` samples: the share of the
    pre-training data kept in the fine-tuning set."""
    out, n = [], 0
    for i in np.random.default_rng([int(seed), 0x5E]).permutation(len(sim)):
        if n >= n_samples:
            break
        out.append(sim[i])
        n += len(sim[i])
    return out


def curve_order(seqs: Seq[Sequence], test_glob: str, seed: int) -> list[str]:
    """The order the learning curve adds training runs: rounds 1-3's (the seeded split_runs order of its training
    runs), then the runs that were its early-stopping runs, so every budget but the last keeps the runs it had
    (fixed before round 4; a coverage order, largest peak force first, was measured beside it and not adopted:
    CHANGELOG, fourth round)."""
    old = FT.split_runs(seqs, train_fraction=None, test_glob=test_glob, seed=seed)
    return list(old.order) + [s.key for s in old.valid]


def _mean_metrics(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean over training seeds of each scalar metric (and of each run's RMSE), with the seeds' RMSEs and spread."""
    out: dict[str, Any] = {k: float(np.mean([r[k] for r in runs])) for k, v in runs[0].items() if isinstance(v, (int, float))}
    out["per_run_rmse"] = {k: float(np.mean([r["per_run_rmse"][k] for r in runs])) for k in runs[0]["per_run_rmse"]}
    rm = [float(r["rmse"]) for r in runs]
    out["rmse_seeds"] = rm
    out["rmse_sd"] = float(np.std(rm, ddof=1)) if len(rm) > 1 else 0.0
    return out


def real_split(p, recording, test_glob: str, seed: int, input_channel: str, target: str, rate: float):
    """The real runs as the loop reads them (re-read through the chain ``p``, its input map), split into training
    runs (in curve_order along the learning curve; early stopping uses the last presses of the budget's own runs,
    FT.split_tail, never a run of another series/cover) and the test runs of ``test_glob``."""
    raw = [reread_through(s, p) for s in FT.load_recording(recording, [input_channel], [target], rate_hz=rate)]
    seqs = FT.apply_map(raw, input_transform(p))
    sp = FT.split_runs(seqs, train_fraction=None, test_glob=test_glob, seed=seed, n_valid=0)
    sp.order = curve_order(seqs, test_glob, seed)
    return sp


def score_on(comp, test: Seq[Sequence]) -> dict[str, Any]:
    """Force metrics of ``comp`` over the runs ``test`` pooled, and each run's RMSE."""
    ref = np.concatenate([s.y[:, 0] for s in test])
    est = np.concatenate([comp.predict(s.x)[:, 0] for s in test])
    r = M.regression_metrics(ref, est)
    r["per_run_rmse"] = {s.key: M.rmse(s.y[:, 0], comp.predict(s.x)[:, 0]) for s in test}
    return r


def two_point_zero_shot(base, p, test: Seq[Sequence], rate: float, how: str = "measured",
                        fit_json: dict[str, Any] | None = None) -> dict[str, Any]:
    """Zero-shot after a two-point calibration on the first test run's first press (``how``: the budget's
    two_point_level), scored on the test data after that press."""
    if how not in TWO_POINT_LEVELS:
        raise ValueError(f"two_point_level must be one of {', '.join(TWO_POINT_LEVELS)} (got {how!r})")
    cal, info = two_point_calibration(p, test[0], rate,
                                      level_shrink=run_level_shrinkage(p, fit_json) if how == "shrunk" else 1.0)
    t0, n0 = test[0], info["calibration_end_sample"]
    after = [Sequence(t0.x[n0:], t0.y[n0:], t0.inputs, t0.targets, t0.units, t0.meta, t0.extra), *test[1:]]
    return {**score_on(_Calibrated(base, cal), after), **info, "level_rule": how,
            "scored_on": "test runs after the calibration press"}


def _evaluate_loop(base, p, recording, test_glob, B, seed, input_channel, target, rate, tick, log, sim=(),
                   scratch: bool = True, fit_json: dict[str, Any] | None = None) -> dict[str, Any]:
    """Step 4: zero-shot, two-point, and the learning curve of fine-tuned / scratch / static curve. ``scratch``
    False leaves the scratch nets out (their rows None: a bench comparing fine-tuning methods, which scratch
    does not depend on)."""
    sp = real_split(p, recording, test_glob, seed, input_channel, target, rate)

    def score(comp, test=None) -> dict[str, Any]:
        return score_on(comp, test or sp.test)

    # training seeds: fine-tuned and scratch each the mean over the same fixed seeds (fixed in the budget)
    seeds = [int(seed) + int(k) for k in range(int(B["n_train_seeds"]))]
    kw = dict(policy=B["policy"], lr=B["lr"], max_epochs=int(B["finetune_epochs"]), patience=int(B["finetune_patience"]),
              norm=B["finetune_norm"], l2sp_alpha=float(B.get("l2sp_alpha", FT.L2SP_ALPHA)),
              l2sp_beta=float(B.get("l2sp_beta", FT.L2SP_BETA)))
    sizes = sorted({k for k in (1, 2, 4) if k < len(sp.train)} | {len(sp.train)})
    n_steps = len(sizes) + 1
    res: dict[str, Any] = {}
    res["zero_shot"] = score(base)
    # the pre-trained net on the real training runs (labelled, never tested on): the training-side sim-to-real gap
    res["zero_shot"]["training_runs_rmse"] = FT.rmse_on(base, sp.train)
    res["zero_shot"]["two_point_gain"] = two_point_zero_shot(base, p, sp.test, rate, B.get("two_point_level", "measured"),
                                                             fit_json)
    tick(1, n_steps)
    full = max(float(max(s.y.max() for s in sp.test)), 1e-9)
    # the sensor's full scale for the tails' loaded presses: the user's rated force, else the training runs' range
    tail_fs = float(B.get("rated_force_n") or max(float(s.y.max()) for s in sp.train))
    tail_kw = dict(full_scale_n=tail_fs, by=B.get("tail_by", "presses"))
    lc = []
    trainings = Trainings()
    try:
        for i, k in enumerate(sizes):
            tr = [s for s in sp.train if s.key in sp.order[:k]]
            heads, tails = FT.split_tail(tr, float(B["valid_tail"]), **tail_kw)
            # round 11's candidate, recorded at every budget whether on or not: the static curve of the heads, the blend
            # weight fitted on the tails' first halves and both scored on their second halves (held out from the weight)
            st_h = StaticCurve(heads)
            t1, t2 = FT.split_tail(tails, 0.5, **tail_kw)
            fts, scs, infos = [], [], []
            # every training of this budget (each seed's grid of fine-tunings and its net from scratch) side by side
            grids, jobs = [], []
            for sd in seeds:
                g, j = _finetune_jobs(base, heads, tails, sd, B, sim, kw)
                grids.append(g)
                jobs += j
                if scratch:
                    jobs.append(("scratch", (base.kind, base.hparams, heads, tails),
                                 {"seed": sd, "max_epochs": int(B["finetune_epochs"]), "patience": int(B["finetune_patience"])}))
            done = iter(trainings.run(jobs))
            for sd, g in zip(seeds, grids):
                ft, fi, reh_ratio, meth = _pick(g, [next(done) for _ in g])
                sc = next(done) if scratch else None
                w_tail = blend_weight(ft, st_h, tails)
                blend_rec = _blend_record(ft, st_h, t1, t2, w_tail, score, sc)
                if B.get("static_blend"):
                    ft = StaticBlend(ft, st_h, w_tail)
                fts.append(score(ft))
                if sc is not None:
                    scs.append(score(sc))
                fv = FT.rmse_on(ft, tails)  # N, on the training runs' validation tails
                sv = FT.rmse_on(sc, tails) if sc is not None else None
                infos.append({"seed": sd, "finetune_epochs": fi["epochs"], "finetune_best_epoch": fi["best_epoch"],
                              "finetune_valid_mse_z_before": fi["valid_mse_z_before"], "finetune_valid_mse_z_best": fi["best_loss"],
                              "finetune_valid_rmse_n": fv, "scratch_valid_rmse_n": sv,
                              "finetune_valid_error_split_n": error_split(ft, tails),
                              **({"linear_probe": fi["linear_probe"]} if "linear_probe" in fi else {}),
                              "rehearsal": reh_ratio, "finetune_method": meth,
                              "scratch_epochs": (getattr(sc, "history", {}) or {}).get("epochs"),
                              "static_blend": blend_rec})
            st = StaticCurve(tr)  # the curve sees every labelled real sample the others see (heads and tails)
            row = {"n_runs": k, "runs": [s.key for s in tr], "finetuned": _mean_metrics(fts),
                   "scratch": _mean_metrics(scs) if scs else None, "static_curve": score(st), "seeds": infos,
                   "pretrained_valid_rmse_n": FT.rmse_on(base, tails), "pretrained_valid_error_split_n": error_split(base, tails)}
            lc.append(row)
            sc_txt = f"{row['scratch']['rmse']:.3f} +- {row['scratch']['rmse_sd']:.3f} N" if scs else "not run"
            log(f"  {k} real run(s): fine-tuned {row['finetuned']['rmse']:.3f} +- {row['finetuned']['rmse_sd']:.3f} N, scratch "
                f"{sc_txt}, static curve {row['static_curve']['rmse']:.3f} N (mean +- sd over {len(seeds)} seeds)")
            tick(i + 2, n_steps)
    finally:
        trainings.close()
    last = lc[-1]
    for k in ("finetuned", "scratch", "static_curve"):
        res[k] = last[k]
    for k in res:
        if res[k] is not None:
            res[k]["rmse_pct_full_scale"] = 100 * res[k]["rmse"] / full
    res["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"] = 100 * res["zero_shot"]["two_point_gain"]["rmse"] / full
    oracle = static_oracle(sp.test)
    oracle["rmse_pct_full_scale"] = 100 * oracle["rmse"] / full

    def sc_(r, k):
        return r["scratch"][k] if r["scratch"] is not None else None

    curve = [{"n_runs": r["n_runs"], "runs": r["runs"], "finetuned_rmse": r["finetuned"]["rmse"], "scratch_rmse": sc_(r, "rmse"),
              "static_curve_rmse": r["static_curve"]["rmse"],
              "finetuned_rmse_sd": r["finetuned"]["rmse_sd"], "scratch_rmse_sd": sc_(r, "rmse_sd"),
              "finetuned_rmse_seeds": r["finetuned"]["rmse_seeds"], "scratch_rmse_seeds": sc_(r, "rmse_seeds"),
              "finetuned_valid_rmse": float(np.mean([x["finetune_valid_rmse_n"] for x in r["seeds"]])),
              "scratch_valid_rmse": float(np.mean([x["scratch_valid_rmse_n"] for x in r["seeds"]])) if scratch else None,
              "pretrained_valid_rmse": r["pretrained_valid_rmse_n"], "pretrained_valid_error_split_n": r["pretrained_valid_error_split_n"],
              "seeds": r["seeds"]} for r in lc]
    tg = {
        "finetuned_beats_scratch_and_static_every_budget": all(r["finetuned_rmse"] < min(r["scratch_rmse"], r["static_curve_rmse"]) for r in curve)
        if scratch else None,
        "one_run_within_1.3x_all_runs": curve[0]["finetuned_rmse"] <= 1.3 * curve[-1]["finetuned_rmse"],
        "pooled_le_12pct": res["finetuned"]["rmse_pct_full_scale"] <= 12.0,
        "zero_shot_two_point_le_25pct": res["zero_shot"]["two_point_gain"]["rmse_pct_full_scale"] <= 25.0,
    }
    return {"recording": str(recording), "split": sp.keys(), "full_scale_n": full, "results": res, "learning_curve": curve,
            "targets": tg, "train_seeds": seeds, "static_oracle": oracle,
            "validation": (f"early stopping on the last {100 * float(B['valid_tail']):.0f} % of each training run's loaded presses (peak >= "
                           f"{100 * FT.LOADED_PRESS_FRACTION:.0f} % of {tail_fs:.3g} N; runs with fewer than two give no tail), cut between presses"
                           if tail_kw["by"] == "presses" else
                           f"early stopping on the last presses of each training run of the budget (about {100 * float(B['valid_tail']):.0f} % "
                           "of its samples, cut between presses)") + "; learn.finetune.split_tail; the pre-trained weights are the first candidate",
            "tail_full_scale_n": tail_fs, "static_blend": bool(B.get("static_blend")),
            "input_map": "%s at %g Hz; the simulated reading is in the real board's units"
                         % (FT.InputMap(input_transform(p)).describe(), rate)}


def _blend_record(net, static, t1, t2, w_tail, score, scratch=None) -> dict[str, Any]:
    """Round 11's candidate on one fit (StaticBlend): w fitted on the tails' first halves, the net and the blend
    scored on the second halves (N); w on the whole tails and the blend's test RMSE beside (never used to choose);
    the same for scratch where it ran (the blend is not scratch's: recorded for the comparison only)."""
    w1 = blend_weight(net, static, t1)
    rec = {"w_first_half": w1, "w_tail": w_tail,
           "second_half_rmse_net_n": FT.rmse_on(net, t2) if t2 else None,
           "second_half_rmse_blend_n": FT.rmse_on(StaticBlend(net, static, w1), t2) if t2 and w1 is not None else None,
           "second_half_rmse_static_n": FT.rmse_on(static, t2) if t2 else None,
           "test_rmse_blend_n": score(StaticBlend(net, static, w_tail))["rmse"] if w_tail is not None else None}
    if scratch is not None:
        ws = blend_weight(scratch, static, t1)
        wt = blend_weight(scratch, static, [*t1, *t2])
        rec.update(scratch_w_first_half=ws, scratch_second_half_rmse_n=FT.rmse_on(scratch, t2) if t2 else None,
                   scratch_second_half_rmse_blend_n=FT.rmse_on(StaticBlend(scratch, static, ws), t2) if t2 and ws is not None else None,
                   scratch_test_rmse_blend_n=score(StaticBlend(scratch, static, wt))["rmse"] if wt is not None else None)
    return rec


def paired_improvement(ref: Seq[float], cand: Seq[float]) -> dict[str, Any]:
    """The eighth round's adoption statistic (CHANGELOG, written before scoring): over K pipeline seeds, the paired
    differences d_p = cand_p - ref_p of the validation-tail RMSE (both on the same pre-trained net); ``improves``
    when their mean is below minus their standard error sd(d) / sqrt(K) (K >= 2)."""
    r, c = np.asarray(ref, float), np.asarray(cand, float)
    if r.shape != c.shape or r.ndim != 1 or len(r) < 2:
        raise ValueError(f"need two equal-length lists of >= 2 values (pipeline seeds); got {r.shape} and {c.shape}")
    d = c - r
    se = float(np.std(d, ddof=1) / np.sqrt(len(d)))
    return {"k": len(d), "ref_mean": float(r.mean()), "cand_mean": float(c.mean()), "diff": d.tolist(),
            "diff_mean": float(d.mean()), "diff_se": se, "improves": bool(d.mean() < -se)}


def error_split(comp, seqs: Seq[Sequence]) -> dict[str, float]:
    """Where a net's force error sits (N): ``level``, the rms over presses of each press's mean error on its
    plateau (>= 90 % of its peak: a gain / level miss), and ``shape``, the rms of the rest within those plateaus
    (creep, dynamics); ``total`` the rms over all samples. Presses as sensors.chain_fit.presses_of."""
    from sensors.chain_fit import presses_of

    lev, shp, allr = [], [], []
    for s in seqs:
        f = s.y[:, 0]
        e = comp.predict(s.x)[:, 0] - f
        allr.append(e)
        for sl in presses_of(f, max(0.1 * float(f.max()), 1e-9)):
            h = sl.start + np.flatnonzero(f[sl] >= 0.9 * f[sl].max())
            if len(h):
                lev.append(float(np.mean(e[h])))
                shp.append(e[h] - np.mean(e[h]))
    rms = lambda a: float(np.sqrt(np.mean(np.square(a)))) if len(a) else float("nan")
    return {"level": rms(np.array(lev)), "shape": rms(np.concatenate(shp)) if shp else float("nan"),
            "total": rms(np.concatenate(allr)), "n_presses": len(lev)}


def _spread_lines(sp: dict[str, Any]) -> list[str]:
    if not sp.get("ratio"):
        return []
    lo, hi = sp["force_range_n"]
    return ["## How hard the simulated presses are", "",
            f"At equal force ({lo:.3g}-{hi:.3g} N, the real training presses' range) the simulated presses' plateau "
            f"readings spread by {sp['sim_ln_reading_sd']:.3f} in ln ({sp['n_sim']} presses) against "
            f"{sp['real_ln_reading_sd']:.3f} for the real training presses ({sp['n_real']}): x{sp['ratio']:.2f} "
            "(> 1: the simulated data are harder to read than the real; sensors.chain_fit.press_spread).", ""]


def _s2r_report(out: Path, m: dict[str, Any]) -> None:
    r = m["results"]
    rows = [[k, fmt(r[k]["rmse"]), fmt(r[k]["rmse_pct_full_scale"]), fmt(r[k]["mae"]), fmt(r[k]["r2"])]
            for k in ("zero_shot", "finetuned", "scratch", "static_curve")]
    z = r["zero_shot"]["two_point_gain"]
    rows.insert(1, ["zero_shot + two-point gain", fmt(z["rmse"]), fmt(z["rmse_pct_full_scale"]), fmt(z["mae"]), fmt(z["r2"])])
    lines = ["# sim2real", "", f"Recording `{m['recording']}`; test runs: {', '.join(m['split']['test'])}; "
             f"full scale {m['full_scale_n']:.1f} N.", "",
             md_table(["model", "RMSE (N)", "% FS", "MAE (N)", "R^2"], rows), "",
             *([f"Not a model: the static curve fitted on the test runs themselves reaches {fmt(m['static_oracle']['rmse'])} N "
                f"({fmt(m['static_oracle']['rmse_pct_full_scale'])} % FS) on them; no monotone memoryless map of the reading "
                "does markedly better there (what the spread of force at equal reading leaves to a static reading).", ""]
               if m.get("static_oracle") else []),
             "## Learning curve (test RMSE, N)", "",
             md_table(["real runs", "fine-tuned (mean +- sd over seeds)", "scratch (mean +- sd)", "static curve",
                       "warm start kept per seed"],
                      [[c["n_runs"], f"{fmt(c['finetuned_rmse'])} +- {fmt(c.get('finetuned_rmse_sd', 0.0))}",
                        f"{fmt(c['scratch_rmse'])} +- {fmt(c.get('scratch_rmse_sd', 0.0))}", fmt(c["static_curve_rmse"]),
                        ", ".join(str(x.get("finetune_method", "plain")) for x in c.get("seeds", []))]
                       for c in m["learning_curve"]]),
             "", f"Training seeds {m.get('train_seeds')}: fine-tuned and scratch are each the mean over them. Two-point "
             f"calibration: unloaded reading {z.get('unloaded_reading', float('nan')):.1f} and a known load of "
             f"{z.get('known_load_n', float('nan')):.2f} N on the first press of {z.get('calibration_run')}; scored after that press.",
             "", *_spread_lines(m.get("steps", {}).get("generate", {}).get("press_spread") or {}),
             "## Targets", "", *[f"- {k}: {'met' if v else 'NOT met'}" for k, v in m["targets"].items()], "",
             "Fit, generation and pre-training details: fit.json, state.json; numbers: metrics.json."]
    (out / "report.md").write_text("\n".join(lines) + "\n")

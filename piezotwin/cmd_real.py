"""`piezotwin pretrain / finetune / fit`: sim-to-real commands, registered on the app of piezotwin.cli.

pretrain  a compensator on a generated dataset, input map recorded in the checkpoint (learn/sim2real.py)
finetune  that checkpoint on a real recording: zero-shot vs fine-tuned vs from scratch (learn/finetune.py)
fit       the velostat film model's parameters to a real recording, writes the fitted preset (sensors/velostat/fit.py)
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated

import typer

from piezotwin.common import _check_writable, app, console, err, fail


def _need_file(p: Path, what: str) -> None:
    if not p.exists():
        fail(f"{what} '{p}' does not exist")


def _need_recording(p: Path) -> None:
    _need_file(p, "recording")
    if p.is_file():
        import h5py

        if not h5py.is_hdf5(p):
            fail(f"recording '{p}' is not an HDF5 recording (import text logs with `piezotwin import`)")


@app.command()
def pretrain(
    data: Annotated[Path, typer.Argument(help="Generated dataset folder (piezotwin generate).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Checkpoint folder.")],
    model: Annotated[str, typer.Option(help="Model kind (tcn, mlp, gru, lstm).")] = "tcn",
    input_channel: Annotated[str, typer.Option("--input", help="Simulated input channel.")] = "resistance_measured",
    transform: Annotated[str, typer.Option(help="Input transform: log | none.")] = "log",
    max_epochs: Annotated[int | None, typer.Option(help="Cap on training epochs.")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the split and the training.")] = 0,
) -> None:
    """Pre-train a compensator on simulated data; the checkpoint records its input map (channel, transform, rate)."""
    from learn.models.base import MODELS, make_model  # noqa: F401
    from learn.sim2real import pretrain as _pretrain

    _need_file(data, "dataset folder")
    if transform not in ("log", "none"):
        fail(f"--transform must be one of: log, none (got '{transform}')")
    import learn.models  # noqa: F401

    if model not in MODELS:
        fail(f"unknown model '{model}' (known: {', '.join(sorted(MODELS))})")
    _check_writable(out)
    hp = {"max_epochs": max_epochs} if max_epochs else {}
    try:
        r = _pretrain(data, out, kind=model, hparams=hp, input_channel=input_channel, transform=transform, seed=seed,
                      progress=err.is_terminal)
    except (ValueError, KeyError) as exc:
        fail(str(exc.args[0] if exc.args else exc))
    console.print(f"wrote {out}: {model}, simulated valid RMSE {r['sim_valid_rmse']:.3f} N, {r['seconds']:.0f} s, "
                  f"input map {r['input_map']}", highlight=False)


@app.command()
def finetune(
    checkpoint: Annotated[Path, typer.Argument(help="Pre-trained checkpoint folder.")],
    recording: Annotated[Path, typer.Argument(help="Real recording (piezotwin import / capture).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Report folder.")],
    train_fraction: Annotated[float | None, typer.Option(help="Share of the runs for fine-tuning (rest: test); with --test-episodes, share of the non-test runs.")] = None,
    test_episodes: Annotated[str | None, typer.Option(help="Glob of episode names held out as the test set (e.g. '*exp2').")] = None,
    freeze: Annotated[str, typer.Option(help="Freeze policy: head (features frozen) | none (all layers).")] = "head",
    lr: Annotated[float, typer.Option(help="Fine-tuning learning rate (Adam).")] = 3e-4,
    max_epochs: Annotated[int, typer.Option(help="Cap on epochs (fine-tuning and from scratch).")] = 300,
    patience: Annotated[int, typer.Option(help="Early-stopping patience on the held-out real runs.")] = 30,
    input_channel: Annotated[str, typer.Option("--input", help="Real input channel (NAME, or NAME[k] for column k of a stream of several values).")] = "sensor",
    target: Annotated[str, typer.Option(help="Label channel.")] = "force",
    rate: Annotated[float | None, typer.Option(help="Resample the real recording to this rate (default: the checkpoint's).")] = None,
    no_curve: Annotated[bool, typer.Option("--no-curve", help="Skip the learning curve.")] = False,
    seed: Annotated[int, typer.Option(help="Seed of the split and the training.")] = 0,
) -> None:
    """Fine-tune a pre-trained compensator on a real recording; report zero-shot / fine-tuned / from scratch."""
    from learn.sim2real import run_finetune

    _need_file(checkpoint, "checkpoint")
    if not (checkpoint / "config.json").is_file():
        fail(f"'{checkpoint}' is not a checkpoint folder (no config.json)")
    _need_recording(recording)
    if train_fraction is not None and not 0 < train_fraction <= 1:
        fail(f"--train-fraction must be in (0, 1] (got {train_fraction})")
    if freeze not in ("head", "none"):
        fail(f"--freeze must be one of: head, none (got '{freeze}')")
    if not lr > 0:
        fail(f"--lr must be > 0 (got {lr})")
    _check_writable(out)
    try:
        m = run_finetune(checkpoint, recording, out, train_fraction=train_fraction, test_glob=test_episodes,
                         policy=freeze, lr=lr, max_epochs=max_epochs, patience=patience, scratch_epochs=max_epochs,
                         input_channel=input_channel, target=target, rate_hz=rate, curve=not no_curve, seed=seed,
                         progress=err.is_terminal, log=lambda s: console.print(s, highlight=False))
    except (ValueError, KeyError) as exc:
        fail(str(exc.args[0] if exc.args else exc))
    r = m["results"]
    console.print(f"test RMSE (N): zero-shot {r['zero_shot']['rmse']:.3f}, zero-shot restandardised "
                  f"{r['zero_shot_restandardised']['rmse']:.3f}, fine-tuned {r['finetuned']['rmse']:.3f}, "
                  f"from scratch {r['scratch']['rmse']:.3f}; wrote {out}/report.md, metrics.json", highlight=False)


@app.command()
def fit(
    preset: Annotated[str, typer.Argument(help="Preset name or scene YAML (velostat family).")],
    recording: Annotated[Path, typer.Argument(help="Real recording with the reading and the force.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Report folder (fitted preset YAML, fit.json, fit.png).")] = Path("runs/fit"),
    input_channel: Annotated[str, typer.Option("--input", help="Real reading channel (proportional to resistance; NAME[k]: column k of a stream of several values).")] = "sensor",
    target: Annotated[str, typer.Option(help="Force channel (N).")] = "force",
    episodes: Annotated[str | None, typer.Option(help="Glob of episodes to fit (default all).")] = None,
    rate: Annotated[float, typer.Option(help="Rate the recording is resampled to for the fit (Hz).")] = 20.0,
    min_force: Annotated[float, typer.Option(help="Samples below this force (N) are left out of the residual.")] = 0.5,
    chain: Annotated[bool, typer.Option("--chain", help="Identify the whole chain (placement spread, creep, divider readout, noise) with bootstrap ranges (sensors/chain_fit.py); always for the divider family.")] = False,
    n_boot: Annotated[int, typer.Option(help="Bootstrap replicates over presses (--chain).")] = 16,
) -> None:
    """Fit the film's conductance law, creep and noise to a real recording (least squares on a fast numpy model)."""
    if chain or preset == "divider":
        return _fit_chain(preset, recording, out, input_channel, target, episodes, rate, n_boot)
    from scenes import ConfigError, load_scene
    from sensors.velostat import fit as VF

    try:
        cfg = load_scene(preset)
    except ConfigError as exc:
        fail(str(exc))
    if cfg.sensor.family != "velostat":
        fail(f"fit supports the velostat family only (preset '{preset}' is {cfg.sensor.family})")
    _need_recording(recording)
    if not rate > 0:
        fail(f"--rate must be > 0 (got {rate})")
    _check_writable(out)
    try:
        runs = VF.load_runs(recording, input_channel=input_channel, target=target, rate_hz=rate, episodes=episodes,
                            min_force_n=min_force)
        res = VF.fit_recording(cfg, runs, min_force_n=min_force)
    except (ValueError, KeyError) as exc:
        fail(str(exc.args[0] if exc.args else exc))
    out.mkdir(parents=True, exist_ok=True)
    name = (Path(preset).stem if Path(preset).is_file() else preset) + "_fitted.yaml"
    yml = VF.write_fitted_preset(preset, res, out / name, str(recording))
    VF.plot_fit(cfg, res, runs, out / "fit.png", min_force)
    info = {"preset": preset, "recording": str(recording), "episodes": [r.key for r in runs], "rate_hz": rate,
            "min_force_n": min_force, "before": res.before.to_json(), "after": res.after.to_json(),
            "error_before": res.err_before, "error_after": res.err_after, "per_run_rms_log_before": res.per_run_before,
            "per_run_rms_log_after": res.per_run_after, "noise_v": res.noise_v, "noise_reading": res.noise_reading,
            "least_squares": res.result, "fitted_preset": str(yml)}
    (out / "fit.json").write_text(json.dumps(info, indent=2))
    eb, ea = res.err_before, res.err_after
    console.print(f"fit error (rms ln reading, {ea['n_samples']} loaded samples): before {eb['rms_log']:.3f} "
                  f"(within press {eb['rms_log_within_press']:.3f}), after {ea['rms_log']:.3f} "
                  f"(within press {ea['rms_log_within_press']:.3f}); wrote {yml}, {out}/fit.json, {out}/fit.png",
                  highlight=False)


def import_with_spec(spec: str, data: Path | None, second: Path | None, out: Path, rate: float | None) -> None:
    """`piezotwin import --spec SPEC DATA`: any column log (sensors/data/column_import.py)."""
    from piezotwin.common import _print_summary
    from sensors.data.column_import import import_columns, load_spec
    from sensors.data.real_import import ImportLogError

    if data is None or second is not None:
        fail("with --spec give one DATA folder (or one log file)")
    _check_writable(out.parent if str(out.parent) else Path("."))
    try:
        sp = load_spec(spec)
        p = import_columns(data, sp, out, rate_hz=rate)
    except ImportLogError as exc:
        fail(str(exc))
    from sensors.data.recording import Recording

    with Recording(p) as rec:
        for ep in rec.episode_ids:
            a = rec.episode_attrs(ep)
            tgt = sp.target
            console.print(f"{ep}: {a['rate_hz']:g} Hz clock{' (period uncertain)' if a.get('time_uncertain') else ''}, "
                          f"{a['duration_s']:.1f} s, {tgt} {a.get(tgt + '_min', float('nan')):.3g} .. "
                          f"{a.get(tgt + '_max', float('nan')):.3g}, {len(a.get('events') or [])} events"
                          + "".join(f"; {k[:-7]}: {len(g)} stretch(es) without a sample (> 1 s, longest "
                                    f"{max(float(x[1]) for x in g):.1f} s) left empty" for k, g in a.items()
                                    if k.endswith("_gaps_s") and len(g))
                          + (f"; not in the file name: {', '.join(a['name_attrs_missing'])}" if a.get("name_attrs_missing") else ""),
                          highlight=False, soft_wrap=True)
        rising = _rising_episodes(rec, sp.input, sp.target)
        if rising and not dict(rec.sensor_attrs).get("adc_full_scale"):
            console.print(f"note: the reading rises with force in {len(rising)} episode(s) ({', '.join(rising[:3])}"
                          f"{', ...' if len(rising) > 3 else ''}): its rest level is not its full scale, so `fit` and "
                          "`sim2real` need the ADC's full scale: add adc_full_scale to the spec's sensor_attrs",
                          highlight=False, soft_wrap=True)
    _print_summary(p)


def _rising_episodes(rec, input_channel: str, target: str) -> list[str]:
    """Episodes whose reading is higher under load than at rest (chain_fit's "low" divider)."""
    import numpy as np

    from sensors.chain_fit import reading_rises

    out = []
    for ep in rec.episode_ids:
        f = np.asarray(rec.read(ep, target), np.float64).reshape(-1)
        y = np.asarray(rec.read(ep, input_channel), np.float64).reshape(len(f), -1)[:, 0]
        ok = np.isfinite(f) & np.isfinite(y)
        if ok.sum() > 10 and reading_rises(f[ok], y[ok]):
            out.append(ep)
    return out


@app.command()
def sim2real(
    family: Annotated[str, typer.Argument(help="Sensor family of the capture (velostat, or divider for an ADC divider array like TAMS).")],
    recording: Annotated[Path, typer.Argument(help="Real recording (piezotwin import).")],
    test_episodes: Annotated[str, typer.Option("--test-episodes", help="Glob of the real test runs (never fitted, never trained on).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Output folder (resumable: finished steps are kept).")],
    episodes: Annotated[int | None, typer.Option(help="Simulated episodes (default: the budget's 96).")] = None,
    pretrain_epochs: Annotated[int | None, typer.Option(help="Pre-training epoch cap (default 40).")] = None,
    n_boot: Annotated[int | None, typer.Option(help="Bootstrap replicates of the fit (default 16).")] = None,
    seed: Annotated[int, typer.Option(help="Root seed (split, fit bootstrap, generation, training).")] = 0,
    input_channel: Annotated[str, typer.Option("--input", help="Real reading channel (one taxel; NAME[k]: column k of a stream of several values, e.g. a capture's velostat[0]).")] = "sensor",
    target: Annotated[str, typer.Option(help="Force channel (N, or a force unit the label is converted from).")] = "force",
    rated_force_n: Annotated[float | None, typer.Option("--rated-force-n", help="The sensor's / rig's rated force (N), "
                             "as the user knows it (never the test runs' maximum): the simulated presses span it.")] = None,
    run_level: Annotated[bool, typer.Option("--run-level", help="Draw each simulated run's ln gain from the fitted "
                         "run-level sd of the press levels (hierarchical levels) instead of the std of the run means.")] = False,
    fit_threshold: Annotated[bool, typer.Option("--fit-threshold", help="Fit the threshold force F_0 (F_eff = F - F_0: "
                             "the force a curved mount carries before the film is loaded) on a board without a readout floor.")] = False,
    creep_linear: Annotated[bool, typer.Option("--creep-linear", help="Linear creep: the fitted creep force "
                            "proportional to the load (the steady law stays a power law).")] = False,
    fit_contact: Annotated[bool, typer.Option("--fit-contact", help="Fit the tip's contact-area term (the share of "
                           "the tip in contact grows as F^(2/3) below the fitted force F_a: a steeper law at small force).")] = False,
    fit_tunnel: Annotated[bool, typer.Option("--fit-tunnel", help="Fit the chain's tunneling term (R_film x "
                          "exp(-F / F_t): the filler gaps close with strain, a law that steepens with force).")] = False,
    latency: Annotated[bool, typer.Option("--latency", help="Read the rig's label latency (the reading leading its "
                       "force label) from the training runs, line the labels up for the fit and delay the generated "
                       "labels by it.")] = False,
    finetune_method: Annotated[str | None, typer.Option("--finetune-method", help="plain, l2sp (L2-SP, Li et al. 2018) "
                               "lpft (LP-FT, Kumar et al. 2022) or shrink_perturb (Ash & Adams 2020), or several "
                               "comma-separated, the one of the lowest validation loss kept per budget and seed; default: "
                               "the budget's (plain,shrink_perturb).")] = None,
    two_point_level: Annotated[str | None, typer.Option("--two-point-level", help="How the two-point calibration's "
                               "known load sets the film level of the presses to come: measured (that press's level) or "
                               "shrunk (its run level under the fitted levels model); default: the budget's.")] = None,
    pipeline_seed: Annotated[int, typer.Option("--pipeline-seed", help="Redraw the generation and the pre-training "
                             "(root seed + 100 x this) with the fit, the run order and the fine-tuning seeds held.")] = 0,
) -> None:
    """Real -> sim -> real: fit the chain, generate randomized data around it, pre-train, fine-tune, report."""
    from learn.sim2real import S2R_BUDGET, run_sim2real

    if family not in ("velostat", "divider"):
        fail(f"sim2real supports the families velostat and divider (got '{family}')")
    _need_recording(recording)
    _check_writable(out)
    b = dict(S2R_BUDGET)
    for k, v in (("n_episodes", episodes), ("pretrain_epochs", pretrain_epochs), ("n_boot", n_boot)):
        if v is not None:
            if v < 1:
                fail(f"--{k.replace('_', '-')} must be >= 1 (got {v})")
            b[k] = v
    if rated_force_n is not None:
        if not (math.isfinite(rated_force_n) and 0 < rated_force_n < 1e6):
            fail(f"--rated-force-n must be a positive finite force in N (got {rated_force_n})")
        b["rated_force_n"] = float(rated_force_n)
    if run_level:
        b["run_level"] = True
    if fit_threshold:
        b["fit_threshold"] = True
    if creep_linear:
        b["creep_linear"] = True
    if fit_contact:
        b["fit_contact"] = True
    if fit_tunnel:
        b["fit_tunnel"] = True
    if latency:
        b["latency"] = True
    if finetune_method is not None:
        from learn.finetune import FINETUNE_METHODS

        ms = [m.strip() for m in finetune_method.split(",")]
        if not all(ms) or any(m not in FINETUNE_METHODS for m in ms):
            fail(f"--finetune-method must be one or more of {', '.join(FINETUNE_METHODS)}, comma-separated "
                 f"(got {finetune_method!r})")
        b["finetune_method"] = ms[0] if len(ms) == 1 else ms
    if two_point_level is not None:
        from learn.sim2real import TWO_POINT_LEVELS

        if two_point_level not in TWO_POINT_LEVELS:
            fail(f"--two-point-level must be one of {', '.join(TWO_POINT_LEVELS)} (got {two_point_level!r})")
        b["two_point_level"] = two_point_level
    if pipeline_seed:
        if not 0 <= pipeline_seed < 10**6:
            fail(f"--pipeline-seed must be in [0, 1e6) (got {pipeline_seed})")
        b["pipeline_seed"] = int(pipeline_seed)
    try:
        import shlex
        import sys

        cmd = "piezotwin " + " ".join(shlex.quote(a) for a in sys.argv[1:])  # recorded in metrics.json
        m = run_sim2real(family, recording, out, test_glob=test_episodes, budget=b, seed=seed, input_channel=input_channel,
                         target=target, progress=err.is_terminal,
                         log=lambda s: console.print(s, highlight=False), command=cmd)
    except (ValueError, KeyError) as exc:
        fail(str(exc.args[0] if exc.args else exc))
    r = m["results"]
    console.print(f"test RMSE (N): zero-shot {r['zero_shot']['rmse']:.3f} (two-point gain "
                  f"{r['zero_shot']['two_point_gain']['rmse']:.3f}), fine-tuned {r['finetuned']['rmse']:.3f} "
                  f"({r['finetuned']['rmse_pct_full_scale']:.1f} % FS), scratch {r['scratch']['rmse']:.3f}, static curve "
                  f"{r['static_curve']['rmse']:.3f}; wrote {out}/report.md, metrics.json", highlight=False)


def _fit_chain(family, recording, out, input_channel, target, episodes, rate, n_boot) -> None:
    from learn.sim2real import _chain_prior
    from sensors import chain_fit as C

    _need_recording(recording)
    if not rate > 0:
        fail(f"--rate must be > 0 (got {rate})")
    _check_writable(out)
    try:
        runs = C.load_real_runs(recording, input_channel=input_channel, target=target, rate_hz=rate, episodes=episodes)
        fit = C.fit_chain(runs, _chain_prior(family, runs), n_boot=n_boot)
        rand = C.randomization_from_fit(fit, runs)
    except (ValueError, KeyError) as exc:
        fail(str(exc.args[0] if exc.args else exc))
    out.mkdir(parents=True, exist_ok=True)
    C.save_fit(fit, out / "chain_fit.json", {"family": family, "recording": str(recording), "fit_runs": [r.key for r in runs],
                                             "randomization": rand.model_dump(mode="json")})
    e = fit.error
    console.print(f"chain fit: {e['n_presses']} presses ({e['n_missed_presses']} without response), within-press rms ln "
                  f"reading {e['rms_log_reading_within_press']:.3f}, press level spread {fit.params.level_log_sd:.2f} (ln), "
                  f"exponent {fit.params.exponent:.3f}; wrote {out}/chain_fit.json", highlight=False)

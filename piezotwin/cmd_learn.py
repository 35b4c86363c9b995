"""`piezotwin experiment ...`: the learn commands, registered on the app of piezotwin.cli.

Kept out of cli.py so that the learn commands and the simulator commands are edited independently;
cli.py imports this module at its bottom.
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import Annotated

import typer

from piezotwin.common import SetOpt, _check_writable, app, console, err, fail


@app.command()
def experiment(
    key: Annotated[str, typer.Argument(help="Paper key (cnt_pdms, fabric, velostat, ntype) or 'all'.")],
    quick: Annotated[bool, typer.Option("--quick", help="Small data and capped epochs: a few minutes on 2 cores.")] = False,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Report folder (default runs/experiment-<key>[-quick]).")] = None,
    data: Annotated[Path | None, typer.Option("--data", help="Dataset folder to make or reuse (default <out>/data).")] = None,
    set_: SetOpt = None,
    models: Annotated[str | None, typer.Option(help="Comma-separated subset of models (the trivial 'mean' always runs).")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the data, the split and the training.")] = 0,
    mode: Annotated[str | None, typer.Option(hidden=True, help="full | quick | tiny (overrides --quick).")] = None,
    train_device: Annotated[str, typer.Option(
        "--train-device", help="Where the gradient-trained nets train: cpu (default: bit-reproducible), cuda, cuda:N "
        "or auto (CUDA when torch sees one). Closed-form and Levenberg-Marquardt fits stay on the CPU.")] = "cpu",
    workers: Annotated[str, typer.Option(
        "--workers", help="CPU processes for the parts that run side by side (ntype: its two tasks; velostat: each BP "
        "hidden-node search), each on one thread: auto (the machine's cores) or a count; 1 runs in this process. "
        "The same numbers at any count >= 2.")] = "auto",
) -> None:
    """Generate (or reuse) data, train the paper's compensators and ours, write report.md + metrics.json + plots."""
    from learn.experiments import EXPERIMENTS, get_experiment
    from learn.train import resolve_device, training_device

    keys = sorted(EXPERIMENTS) if key == "all" else [key]
    for k in keys:
        if k not in EXPERIMENTS:
            fail(f"unknown experiment '{k}' (known: {', '.join(sorted(EXPERIMENTS))}, all)")
    try:
        resolve_device(train_device)
    except ValueError as exc:
        fail(f"--train-device: {exc}")
    if workers == "auto":
        n_workers = os.cpu_count() or 1
    elif workers.isdigit() and int(workers) >= 1:
        n_workers = int(workers)
    else:
        fail(f"--workers must be auto or a whole number >= 1 (got '{workers}')")
    run_mode = mode or ("quick" if quick else "full")
    sel = [m.strip() for m in models.split(",") if m.strip()] if models else None
    for k in keys:
        exp = get_experiment(k)
        if run_mode not in exp.MODES:
            fail(f"--mode must be one of: {', '.join(exp.MODES)} (got '{run_mode}')")
        if sel is not None:
            known = set(exp.MODES[run_mode].models)
            bad = [m for m in sel if m not in known]
            if bad:
                fail(f"unknown model(s) {', '.join(bad)} for {k} (known: {', '.join(sorted(known))})")
        dest = out / k if (out is not None and len(keys) > 1) else out
        dest = dest or Path("runs") / (f"experiment-{k}" + ("" if run_mode == "full" else f"-{run_mode}"))
        _check_writable(dest)
        try:
            extra = {"workers": n_workers} if "workers" in inspect.signature(exp.run).parameters else {}
            with training_device(train_device):
                exp.run(dest, mode=run_mode, data_dir=data, overrides=list(set_ or []), models=sel, seed=seed,
                        progress=err.is_terminal, log=lambda s: console.print(s, highlight=False), **extra)
        except ValueError as exc:
            fail(str(exc))

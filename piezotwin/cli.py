"""piezotwin command line: parses, calls the packages, shows progress. No physics here.

Bad input (unknown preset or field, wrong unit, unwritable folder, unreadable file) prints one line
naming the problem and exits with code 2, before anything is written.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from piezotwin.common import (
    SetOpt, _check_writable, _load, _print_dataset_header, _print_dataset_summary, _print_summary, _quiet_warp, app, console,
    err, fail,
)



TIMINGS_ENV = "PIEZOTWIN_TIMINGS_JSON"


T0_ENV = "PIEZOTWIN_T0_WALL"  # the bench's time.time() just before it started this process (start-up timing)


def _dump_timings(cli: dict[str, float]) -> None:
    """Where $PIEZOTWIN_TIMINGS_JSON names a file (benches), write the last run's seconds per stage there: the
    shards' stages, and the command's own (`cli`: before the shards, the dataset summary; with $PIEZOTWIN_T0_WALL
    also process start -> `generate` and the time of this write, so the bench gets the exit as wall - it)."""
    path = os.environ.get(TIMINGS_ENV)
    if not path:
        return
    import json
    import time

    from simulate.generation.executors import LAST_GENERATE_SECONDS
    from simulate.generation.feed import LAST_RUN_SECONDS

    t0 = os.environ.get(T0_ENV)
    if t0:
        cli = {**cli, "dumped at (from process start)": time.time() - float(t0)}
    Path(path).write_text(json.dumps({"generate": LAST_GENERATE_SECONDS, "feed": LAST_RUN_SECONDS, "cli": cli}, indent=1))


@app.command()
def generate(
    scene: Annotated[str, typer.Argument(help="Preset name (e.g. cnt_pdms) or a scene YAML file.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Output dataset folder.")] = Path("runs/default"),
    episodes: Annotated[int | None, typer.Option(help="Number of episodes.")] = None,
    seed: Annotated[int | None, typer.Option(help="Root seed.")] = None,
    set_: SetOpt = None,
    backend: Annotated[str, typer.Option(help="Sensor kernels: warp | numpy.")] = "warp",
    device: Annotated[str, typer.Option(help="Warp device: auto (CUDA when present) | cpu | cuda | cuda:N.")] = "auto",
    executor: Annotated[str, typer.Option(help="Where shards run: local (process pool when --workers > 1) | ray.")] = "local",
    address: Annotated[str | None, typer.Option(help="Ray cluster address (ray executor; default: start a local one).")] = None,
    shards: Annotated[int | None, typer.Option(help="Number of shards (sets generation.episodes_per_shard).")] = None,
    workers: Annotated[int | None, typer.Option(help="Worker processes (local pool; writers of the GPU feed) or CPUs of a local Ray cluster; default: 1, or up to 8 writers where the GPU feed runs.")] = None,
    physics: Annotated[str, typer.Option(help="Contact stage: auto (MuJoCo Warp where CUDA and mujoco_warp are, else C MuJoCo) | mujoco (C, CPU) | mujoco_warp (batched worlds on --device).")] = "auto",
) -> None:
    """Generate a dataset: HDF5 shards + manifest.json. Resumes at the first missing shard.

    By default (--physics auto --device auto) a machine with a CUDA device and mujoco_warp steps the worlds on
    the GPU; elsewhere C MuJoCo on the CPU. The line `engine: ...` says what ran and why."""
    import time

    t_in, wall_in = time.perf_counter(), time.time()
    extra = []
    if physics not in ("mujoco", "mujoco_warp", "auto"):
        fail(f"--physics must be one of: mujoco, mujoco_warp, auto (got '{physics}')")
    if episodes is not None:
        extra.append(f"generation.episodes={episodes}")
    if seed is not None:
        extra.append(f"generation.root_seed={seed}")
    if executor not in ("local", "ray"):
        fail(f"--executor must be one of: local, ray (got '{executor}')")
    if workers is not None and workers < 1:
        fail(f"--workers must be >= 1 (got {workers})")
    if address and executor != "ray":
        fail("--address needs --executor ray")
    if executor == "ray":
        import importlib.util

        if importlib.util.find_spec("ray") is None:
            fail("--executor ray needs Ray: pip install 'piezotwin[ray]'")
    cfg = _load(scene, set_, extra)
    if shards is not None:
        if not 1 <= shards <= cfg.generation.episodes:
            fail(f"--shards must be between 1 and the number of episodes ({cfg.generation.episodes}); got {shards}")
        extra.append(f"generation.episodes_per_shard={-(-cfg.generation.episodes // shards)}")
        cfg = _load(scene, set_, extra)
    if backend not in ("warp", "numpy"):
        fail(f"--backend must be one of: warp, numpy (got '{backend}')")
    if device not in ("cpu", "cuda", "auto") and not device.startswith("cuda:"):
        fail(f"--device must be one of: cpu, cuda, cuda:N, auto (got '{device}')")
    from simulate.generation import feed as gpu_feed

    if gpu_feed.feed_likely(cfg, physics, device, backend, executor, workers):
        gpu_feed.prestart_physics()  # their spawn and imports overlap the engine choice and Warp init below
    try:  # an error before the feed takes the physics processes started ahead stops them (not waited for)
        from simulate.generation.choice import choose

        try:
            chosen = choose(cfg, physics, device, workers, backend,
                            step_asked=any(str(x).strip().startswith("sampling.physics_timestep_s") for x in (set_ or [])))
        except ValueError as exc:
            fail(str(exc))
        if chosen.overrides:
            cfg = _load(scene, set_, extra + chosen.overrides)
        device, workers = chosen.device, chosen.workers
        if backend == "warp":
            from sensors.warp_setup import resolve_device

            try:
                device = resolve_device(device)
            except ValueError as exc:
                fail(str(exc))
        _check_writable(out)
        _quiet_warp()
        from simulate.generation.run import check_record

        try:
            check_record(cfg)
        except ValueError as exc:
            fail(str(exc))
    except typer.Exit:
        gpu_feed.release_prestarted()
        raise
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from simulate.generation.executors import ShardFailedError
    from simulate.generation.executors import generate as run_generate
    from simulate.generation.run import n_shards

    err.print(chosen.line(), highlight=False, soft_wrap=True)
    with Progress(
        TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("episodes"),
        TimeElapsedColumn(), TimeRemainingColumn(), console=err, transient=False,
    ) as bar:
        task = bar.add_task(f"{cfg.name} ({n_shards(cfg)} shards)", total=cfg.generation.episodes)
        skipped = []

        def on_shard(i: int, n: int, was_skipped: bool) -> None:
            if was_skipped:
                skipped.append(i)
            bar.advance(task, n)

        t_ready = time.perf_counter()
        try:
            manifest = run_generate(
                cfg, out, executor=executor, workers=workers, address=address, backend=backend, device=device,
                on_shard=on_shard,
            )
        except ShardFailedError as exc:
            fail(str(exc))
    t_gen = time.perf_counter()
    if skipped:
        console.print(f"resumed: {len(skipped)} complete shard(s) kept")
    console.print(f"wrote {manifest}")
    console.print(chosen.line(), highlight=False, soft_wrap=True)
    _print_dataset_summary(out)
    cli_s = {"before the shards (engine choice, Warp init, checks)": t_ready - t_in, "generate": t_gen - t_ready,
             "dataset summary": time.perf_counter() - t_gen}
    if os.environ.get(T0_ENV):
        cli_s["process start -> generate (interpreter, imports)"] = wall_in - float(os.environ[T0_ENV])
    _dump_timings(cli_s)


@app.command()
def inspect(path: Annotated[Path, typer.Argument(help="A recording (.h5) or a dataset folder.")]) -> None:
    """Summary table of a recording: episodes, duration, channels with units and ranges."""
    if path.is_dir():
        from sensors.data.manifest import ManifestError, read_manifest

        try:
            m = read_manifest(path)
        except ManifestError as exc:
            fail(str(exc))
        _print_dataset_header(m)
        for s in m["shards"]:
            _print_summary(path / s["file"])
        return
    _print_summary(path)


@app.command()
def characterize(
    scene: Annotated[str, typer.Argument(help="Preset name or scene YAML.")] = "cnt_pdms",
    set_: SetOpt = None,
    plot: Annotated[Path | None, typer.Option(help="Write the characterization plot as a PNG here.")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Write the numbers as JSON here.")] = None,
    backend: Annotated[str, typer.Option(help="warp | numpy")] = "warp",
) -> None:
    """Hysteresis error (% FSO), loop area and phase lag per loading frequency, beside the paper's figure."""
    cfg = _load(scene, set_, [])
    _quiet_warp()
    from simulate.characterize import characterize as run_char

    try:
        report = run_char(cfg, backend=backend)
    except ValueError as exc:
        fail(str(exc))
    t = Table(title=report.title)
    for col in report.columns:
        t.add_column(col, justify="right")
    for row in report.rows:
        t.add_row(*row)
    console.print(t)
    for note in report.notes:
        console.print(note)
    if json_out:
        import json

        json_out.write_text(json.dumps(report.metrics, indent=2))
        console.print(f"wrote {json_out}")
    if plot and report.plot:
        _check_writable(plot.parent if str(plot.parent) else Path("."))
        report.plot(str(plot))
        console.print(f"wrote {plot}")


@app.command()
def presets() -> None:
    """List the scene presets."""
    from scenes import list_presets

    for p in list_presets():
        console.print(p)


# command modules register on `app` (piezotwin.common) when imported (one line each)
from piezotwin import cmd_learn  # noqa: F401
from piezotwin import cmd_viz  # noqa: F401
from piezotwin import cmd_serial  # noqa: F401
from piezotwin import cmd_real  # noqa: F401
from piezotwin import cmd_calibrate  # noqa: F401


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    # `python -m piezotwin.cli` runs this file as __main__, a second copy of the module; the command modules
    # register on the copy imported by name, so run that one
    from piezotwin.cli import app as named_app

    sys.exit(named_app())

"""What every command module shares: the typer app, the consoles, `fail` (one line, exit 2) and small checks.

The command modules (cli.py and cmd_*.py) import from here; piezotwin/cli.py imports them all, so the import
graph has no circle.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True, help="Piezoresistive tactile sensor simulator.")
console = Console()
err = Console(stderr=True)


def fail(msg: str) -> None:
    err.print(f"[bold red]error:[/] {msg}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def _quiet_warp() -> None:
    from sensors.warp_setup import init_warp

    init_warp()


def _load(scene: str, overrides: list[str] | None, extra: list[str]):
    from scenes import ConfigError, load_scene

    try:
        return load_scene(scene, list(overrides or []) + extra)
    except ConfigError as exc:
        fail(str(exc))


def _check_writable(out: Path) -> None:
    probe = next((p for p in (out, *out.parents) if p.exists()), Path("."))
    if not probe.is_dir():
        fail(f"output folder '{out}' cannot be made: '{probe}' is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        fail(f"output folder '{out}' is not writable")


SetOpt = Annotated[Optional[list[str]], typer.Option("--set", help="Override a config field: key.path=value (repeatable).")]


def unreadable(path: Path, exc: BaseException) -> None:
    """fail() with one line for a recording that cannot be read (wrong format, damaged HDF5)."""
    msg = (str(exc).splitlines() or [type(exc).__name__])[0].removeprefix(f"{path}: ")
    fail(f"'{path}' is not a readable recording: {msg}")


def _print_summary(path: Path) -> None:
    from sensors.data.recording import RecordingError, read_recording_summary

    if not path.is_file():
        fail(f"'{path}' does not exist")
    try:
        s = read_recording_summary(path)
    except (RecordingError, OSError, RuntimeError) as exc:
        unreadable(path, exc)
    console.print(
        f"[bold]{path}[/]  source={s['source']}  episodes={s['n_episodes']}  duration={s['duration_s']:.1f} s  "
        f"samples={s['n_samples']}  seed={s['root_seed']}  shard={s['shard_index']}", highlight=False, soft_wrap=True,
    )
    console.print(f"content_sha256 {s['content_sha256']}", highlight=False, soft_wrap=True)
    t = Table(show_header=True, header_style="bold")
    for col in ("channel", "units", "dims", "frame", "min", "max"):
        t.add_column(col, justify="right" if col in ("min", "max") else "left")
    for name, c in s["channels"].items():
        fmt = lambda v: "-" if v is None else f"{v:.4g}"  # noqa: E731
        t.add_row(name, c["units"], ",".join(c["dim_names"]), str(c["frame_shape"]), fmt(c["min"]), fmt(c["max"]))
    console.print(t)

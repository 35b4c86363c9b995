"""What every command module shares: the typer app, the consoles, `fail` (one line, exit 2) and small checks.

The command modules (cli.py and cmd_*.py) import from here; piezotwin/cli.py imports them all, so the import
graph has no circle.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console, ConsoleDimensions
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True, help="Piezoresistive tactile sensor simulator.")

PIPE_WIDTH = 250  # columns when the output is not a terminal: tables never cut names ("resistance_meas…")


class _Console(Console):
    """A console that, written to a pipe or a file, is wide enough that tables keep whole names (a terminal
    keeps its own width)."""

    @property
    def size(self) -> ConsoleDimensions:
        s = Console.size.fget(self)
        return s if self.is_terminal or self._width is not None else ConsoleDimensions(max(s.width, PIPE_WIDTH), s.height)

    @size.setter
    def size(self, new_size: tuple[int, int]) -> None:
        Console.size.fset(self, new_size)


console = _Console()
err = _Console(stderr=True)


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


SetOpt = Annotated[list[str] | None, typer.Option("--set", help="Override a config field: key.path=value (repeatable).")]


def unreadable(path: Path, exc: BaseException) -> None:
    """fail() with one line for a recording that cannot be read (wrong format, damaged HDF5)."""
    msg = (str(exc).splitlines() or [type(exc).__name__])[0].removeprefix(f"{path}: ")
    fail(f"'{path}' is not a readable recording: {msg}")


def _summary(path: Path) -> dict:
    from sensors.data.recording import RecordingError, read_recording_summary

    if not path.is_file():
        fail(f"'{path}' does not exist")
    try:
        return read_recording_summary(path)
    except (RecordingError, OSError, RuntimeError) as exc:
        unreadable(path, exc)
    raise AssertionError  # unreachable: unreadable() exits


# Measured serial summary of the first 8 shards on the H100 host (user-cli-h100-s12-*.json, "dataset summary"):
# ntype 400 episodes 5.5 s, velostat 96 episodes 2.8 s, cnt_pdms 128 episodes 1.8 s, fabric_1 64 episodes 1.0 s:
# 14-30 ms per episode (per-dataset HDF5 overhead and decompression), while a spawned reader process starts in ~0.7 s
PARALLEL_SUMMARY_EPISODES = 64  # estimate: from about 1 s of serial reading, the readers win
PARALLEL_SUMMARY_MIN_CPUS = 8  # estimate: a machine of fewer cores (the 2-core CI box) keeps the serial read and its timing


def _summaries(files: list[Path], parallel: bool | None = None, episodes: int = 0) -> list[dict]:
    """`_summary` of each file, in order. parallel=None: one spawned reader process per file (at most 8) where
    the files hold >= PARALLEL_SUMMARY_EPISODES episodes (`episodes`, from the manifest) and the machine has >=
    PARALLEL_SUMMARY_MIN_CPUS cores (h5py's lock serialises threads); else one after another. Same dicts either way
    (the same function reads each file)."""
    for p in files:
        if not p.is_file():
            fail(f"'{p}' does not exist")
    if parallel is None:
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        parallel = len(files) > 1 and cpus >= PARALLEL_SUMMARY_MIN_CPUS and episodes >= PARALLEL_SUMMARY_EPISODES
    if not parallel:
        return [_summary(p) for p in files]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from sensors.data.recording import RecordingError, read_recording_summary

    try:
        with ProcessPoolExecutor(min(len(files), 8), mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(read_recording_summary, p) for p in files]
            out = []
            for p, f in zip(files, futures):
                try:
                    out.append(f.result())
                except BrokenProcessPool:
                    raise
                except (RecordingError, OSError, RuntimeError) as exc:
                    unreadable(p, exc)
            return out
    except BrokenProcessPool:  # a reader died (memory): read them here, as the serial path does
        return [_summary(p) for p in files]


def _channel_table(channels: dict, title: str | None = None) -> Table:
    t = Table(show_header=True, header_style="bold", title=title)
    for col in ("channel", "units", "dims", "frame", "min", "max"):
        t.add_column(col, justify="right" if col in ("min", "max") else "left")
    fmt = lambda v: "-" if v is None else f"{v:.4g}"
    for name, c in channels.items():
        t.add_row(name, c["units"], ",".join(c["dim_names"]), str(tuple(c["frame_shape"])), fmt(c["min"]), fmt(c["max"]))
    return t


def _print_summary(path: Path) -> None:
    s = _summary(path)
    console.print(
        f"[bold]{path}[/]  source={s['source']}  episodes={s['n_episodes']}  duration={s['duration_s']:.1f} s  "
        f"samples={s['n_samples']}  seed={s['root_seed']}  shard={s['shard_index']}", highlight=False, soft_wrap=True,
    )
    console.print(f"content_sha256 {s['content_sha256']}", highlight=False, soft_wrap=True)
    console.print(_channel_table(s["channels"]))


def _print_dataset_header(m: dict) -> None:
    console.print(
        f"dataset [bold]{m.get('name')}[/]: {m.get('total_episodes', '?')} episodes in {len(m['shards'])} shards, "
        f"root_seed={m.get('root_seed')}, splits " + ", ".join(f"{k}={len(v)}" for k, v in m["splits"].items()),
        highlight=False, soft_wrap=True,
    )
    console.print(f"content_sha256 {m.get('content_sha256') or '- (manifest written before content hashes)'}",
                  highlight=False, soft_wrap=True)


def _print_dataset_summary(directory: Path, max_shards: int = 8) -> None:
    """The whole dataset in one table: totals from the manifest, channel ranges merged over its shards. From the
    manifest's "summary" (its shards' stored summaries merged when it was written: no shard opened) where it has
    one; else the data of the first `max_shards` shards is read (a larger dataset says so in the title)."""
    from sensors.data.manifest import ManifestError, read_manifest
    from sensors.data.recording import merge_summaries

    try:
        m = read_manifest(directory)
    except ManifestError as exc:
        fail(str(exc))
    _print_dataset_header(m)
    files = [directory / s["file"] for s in m["shards"]]
    merged, n_read = m.get("summary"), len(files)
    if not (isinstance(merged, dict) and {"n_samples", "duration_s", "channels"} <= set(merged)):
        sums = _summaries(files[:max_shards],
                          episodes=sum(len(s.get("episodes", ())) for s in m["shards"][:max_shards]))
        merged, n_read = merge_summaries(sums), len(sums)
    over = (f"all {len(files)} shards" if n_read == len(files)
            else f"the first {n_read} of {len(files)} shards (piezotwin inspect {directory} reads all)")
    console.print(f"{merged['n_samples']} samples, {merged['duration_s']:.1f} s of recording in {over}",
                  highlight=False, soft_wrap=True)
    console.print(_channel_table(merged["channels"], title=f"channels, ranges over {over}"))

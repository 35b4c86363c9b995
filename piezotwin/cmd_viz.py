"""`piezotwin show`, `piezotwin export`, `piezotwin plot`: look at a recording (registered on cli.app).

Rendering needs the `viz` extra (pyvista, imageio, imageio-ffmpeg); it is imported only by these commands.
Bad input (missing file, unknown field, episode or time out of range, wrong suffix) is one line, exit 2.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer

from piezotwin.common import _check_writable, app, console, err, fail, unreadable


@contextmanager
def _open(path: Path, episode: str | None, fields: list[str] | None) -> Iterator:
    from sensors.data.recording import Recording, RecordingError
    from simulate.pictures.fields import FieldError, load_episode

    if path.is_dir():
        shards = sorted(path.glob("shard-*.h5"))
        if not shards:
            fail(f"'{path}' is a folder with no shard-*.h5 recordings")
        path = shards[0]
    if not path.is_file():
        fail(f"'{path}' does not exist")
    try:
        rec = Recording(path)
    except (RecordingError, OSError, RuntimeError) as exc:
        unreadable(path, exc)
    try:
        with rec:
            try:
                ev = load_episode(rec, episode, fields)
            except (RecordingError, OSError, RuntimeError) as exc:  # damaged data (failed checksum, B-tree)
                unreadable(path, exc)
            yield ev
    except FieldError as exc:
        fail(str(exc))


def _bar(label: str):
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("frames"),
                    TimeElapsedColumn(), TimeRemainingColumn(), console=err, transient=False)


def _viz_errors():
    from simulate.pictures.fields import FieldError
    from simulate.pictures.render import VizUnavailable

    return (FieldError, VizUnavailable)


Episode = Annotated[str | None, typer.Option("--episode", "-e", help="Episode index (0..) or id (ep-000003). Default: the first.")]


@app.command()
def show(
    recording: Annotated[Path, typer.Argument(help="A recording (.h5) or a dataset folder (its first shard).")],
    episode: Episode = None,
    time: Annotated[float | None, typer.Option("--time", "-t", help="Time in s (nearest sample). Default: peak force.")] = None,
    field: Annotated[str, typer.Option("--field", "-f", help="deformation | pressure | strain | resistance | force_taxel")] = "deformation",
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Write a .png (or with --animate an .mp4/.gif) instead of opening a window.")] = None,
    animate: Annotated[bool, typer.Option("--animate", help="Animate the whole episode into -o FILE.mp4|.gif.")] = False,
    exaggeration: Annotated[float | None, typer.Option(help="Deformation scale factor (default: a round factor showing the peak at ~30 % of thickness).")] = None,
    view: Annotated[str, typer.Option(help="iso | top")] = "iso",
    size: Annotated[str, typer.Option(help="Image size WxH in pixels.")] = "896x640",
    fps: Annotated[float, typer.Option(help="Animation frame rate; frames are sampled for real-time playback.")] = 25.0,
    max_frames: Annotated[int | None, typer.Option(help="At most this many animation frames.")] = None,
) -> None:
    """Render the sensor at one instant: deformed body coloured by a field, indenter where it was.

    With a display and no -o: an interactive window. Without a display: a PNG (named after the recording,
    episode and field) is written and its path printed.
    """
    from simulate.pictures.fields import FIELDS

    if field not in FIELDS:
        fail(f"unknown field '{field}' (allowed: {', '.join(FIELDS)})")
    if view not in ("iso", "top"):
        fail(f"--view must be iso or top (got '{view}')")
    try:
        w, h = (int(v) for v in size.lower().split("x"))
        assert 16 <= w <= 8192 and 16 <= h <= 8192
    except (ValueError, AssertionError):
        fail(f"--size must be WxH in pixels, 16..8192 (got '{size}')")
    if exaggeration is not None and not exaggeration > 0:
        fail(f"--exaggeration must be > 0 (got {exaggeration})")
    if animate:
        if out is None or out.suffix.lower() not in (".mp4", ".gif"):
            fail("--animate needs -o FILE.mp4 or -o FILE.gif")
        if not fps > 0:
            fail(f"--fps must be > 0 (got {fps})")
    if max_frames is not None and max_frames < 1:
        fail(f"--max-frames must be >= 1 (got {max_frames}; leave it out for every frame)")
    elif out is not None and out.suffix.lower() != ".png":
        fail(f"-o '{out}' must end in .png (for a movie add --animate)")
    if out is not None:
        _check_writable(out.parent if str(out.parent) else Path("."))
    from simulate.pictures.render import (
        RenderOptions,
        has_display,
        render_animation,
        render_frame,
        show_window,
    )

    opts = RenderOptions(window_size=(w, h), view=view, exaggeration=exaggeration)
    with _open(recording, episode, [field]) as ev:
        errors = _viz_errors()
        try:
            if animate:
                with _bar(f"{ev.ep_id} {field}") as bar:
                    task = bar.add_task(f"{ev.ep_id} {field}", total=None)

                    def on_frame(done: int, total: int) -> None:
                        bar.update(task, completed=done, total=total)

                    path, info = render_animation(ev, field, out, fps=fps, max_frames=max_frames, opts=opts, on_frame=on_frame)
                console.print(f"wrote {path}  (deformation x{info.exaggeration:g}, {field} {info.clim[0]:.3g}..{info.clim[1]:.3g} {info.unit})")
                return
            k = ev.index_at(time) if time is not None else ev.peak_index()
            if out is None and has_display():
                show_window(ev, field, k, opts)
                return
            if out is None:
                out = Path(f"{Path(ev.path).stem}-{ev.ep_id}-{field}.png")  # the shard read, also for a dataset folder
                _check_writable(Path("."))
                console.print("no display: rendering offscreen")
            _, info = render_frame(ev, field, k, out, opts)
        except errors as exc:
            fail(str(exc))
    console.print(
        f"wrote {out}  (t = {info.time_s:.2f} s, F = {info.force_n:.2f} N, deformation x{info.exaggeration:g}, "
        f"{field} {info.clim[0]:.3g}..{info.clim[1]:.3g} {info.unit})"
    )


@app.command()
def export(
    recording: Annotated[Path, typer.Argument(help="A recording (.h5) or a dataset folder (its first shard).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Output folder: <episode>.pvd + <episode>/body_NNNNNN.vtu, indenter_NNNNNN.vtu per sample.")] = Path("vtk"),
    episode: Episode = None,
    stride: Annotated[int, typer.Option(help="Write every N-th sample.")] = 1,
) -> None:
    """VTK time series of an episode (.vtu per sample + .pvd) that opens in ParaView."""
    if stride < 1:
        fail(f"--stride must be >= 1 (got {stride})")
    _check_writable(out)
    from simulate.pictures.export import export_episode

    with _open(recording, episode, None) as ev:
        try:
            with _bar("export") as bar:
                task = bar.add_task(f"{ev.ep_id}", total=None)
                pvd = export_episode(ev, out, stride=stride, on_frame=lambda d, n: bar.update(task, completed=d, total=n))
        except _viz_errors() as exc:
            fail(str(exc))
    console.print(f"wrote {pvd}  (open in ParaView; Warp By Vector 'displacement' to see the deflection)")


@app.command()
def plot(
    recording: Annotated[Path, typer.Argument(help="A recording (.h5) or a dataset folder (its first shard).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="PNG to write.")] = Path("episode.png"),
    episode: Episode = None,
    field: Annotated[str, typer.Option("--field", "-f", help="Field for the per-taxel peak map.")] = "deformation",
) -> None:
    """One episode at a glance (matplotlib): force-resistance loop, time series, per-taxel peak map."""
    from simulate.pictures.fields import FIELDS

    if field not in FIELDS:
        fail(f"unknown field '{field}' (allowed: {', '.join(FIELDS)})")
    if out.suffix.lower() != ".png":
        fail(f"-o '{out}' must end in .png")
    _check_writable(out.parent if str(out.parent) else Path("."))
    from simulate.pictures.plots import episode_overview

    with _open(recording, episode, None) as ev:
        if field not in ev.fields:
            fail(f"episode {ev.ep_id} has no '{field}' field")
        episode_overview(ev, out, field)
    console.print(f"wrote {out}")

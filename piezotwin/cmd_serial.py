"""Real sensors on the command line: ``capture`` from serial boards, ``import`` text logs, ``serve`` a
virtual board. Registers on the typer app of piezotwin.cli (imported at the bottom of that module).

Bad input (unknown protocol, unreadable or malformed log, bad URL) is one line and exit code 2. A port
that vanishes mid-capture is one line and exit code 1, after the recording is written up to the last
flush.
"""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path
from typing import Annotated

import typer

from piezotwin.common import _check_writable, _print_summary, app, console, err, fail
from sensors.serial.codec import PROTOCOLS

_PROTO_HELP = "Framing: " + " | ".join(PROTOCOLS) + "."


def _check_protocol(p: str | None, opt: str) -> None:
    if p is not None and p not in PROTOCOLS:
        fail(f"unknown protocol '{p}' for {opt} (allowed: {', '.join(PROTOCOLS)})")


@app.command()
def capture(
    out: Annotated[Path, typer.Option("-o", "--out", help="Recording to write (.h5); the raw log is OUT.rawlog.")],
    port: Annotated[str | None, typer.Option(help="Port URL: /dev/ttyUSB0, socket://HOST:PORT, loop://, a pty path.")] = None,
    protocol: Annotated[str, typer.Option(help=_PROTO_HELP)] = "text",
    baudrate: Annotated[int, typer.Option(help="Baud rate.")] = 115200,
    n_values: Annotated[int | None, typer.Option(help="Values per sample (poll: float32 per reply, default 1).")] = None,
    name: Annotated[str, typer.Option(help="Stream name (channel name in the recording).")] = "s0",
    units: Annotated[str, typer.Option(help="Units of the stream's values.")] = "raw",
    poll_hz: Annotated[float | None, typer.Option(help="poll: cap on the polling rate (default: as fast as replies come).")] = None,
    port2: Annotated[str | None, typer.Option(help="A second port (e.g. a load cell).")] = None,
    protocol2: Annotated[str, typer.Option(help="Framing of the second port.")] = "text",
    baudrate2: Annotated[int, typer.Option(help="Baud rate of the second port.")] = 115200,
    n_values2: Annotated[int | None, typer.Option(help="Values per sample of the second port.")] = None,
    name2: Annotated[str, typer.Option(help="Name of the second stream.")] = "s1",
    units2: Annotated[str, typer.Option(help="Units of the second stream.")] = "raw",
    duration: Annotated[float | None, typer.Option(help="Stop after this many seconds (default: Ctrl-C).")] = None,
    flush_s: Annotated[float, typer.Option(help="Flush + fsync the raw log this often (s, <= 1).")] = 0.5,
    reconnect_s: Annotated[float, typer.Option(help="Keep retrying a vanished port this long (s) before giving up.")] = 0.0,
    rebuild: Annotated[bool, typer.Option("--rebuild", help="Only rebuild OUT from OUT.rawlog (after a crash or a parser fix).")] = False,
) -> None:
    """Capture one or two serial streams (host-time stamped, aligned) into a recording; appends on restart."""
    from sensors.serial.capture import (
        CaptureError,
        StreamSpec,
        build_recording,
        rawlog_path,
    )
    from sensors.serial.capture import capture as run_capture

    _check_protocol(protocol, "--protocol")
    _check_protocol(protocol2, "--protocol2")
    if rebuild:
        try:
            p = build_recording(rawlog_path(out), out)
        except CaptureError as exc:
            fail(str(exc))
        console.print(f"rebuilt {p} from {rawlog_path(out)}")
        return
    if port is None:
        fail("--port is required (or --rebuild)")
    if duration is not None and duration <= 0:
        fail(f"--duration must be > 0 s, got {duration}")

    _check_writable(out.parent if str(out.parent) else Path("."))
    streams = [StreamSpec(port, protocol, name, baudrate, n_values, units, poll_hz)]
    if port2 is not None:
        streams.append(StreamSpec(port2, protocol2, name2, baudrate2, n_values2, units2))

    last = {}

    def progress(stats: list[dict], elapsed: float) -> None:
        parts = []
        for s, st in zip(streams, stats):
            prev = last.get(s.name, (0, 0.0))
            rate = (st.get("frames", 0) - prev[0]) / max(1e-9, elapsed - prev[1])
            last[s.name] = (st.get("frames", 0), elapsed)
            parts.append(f"{s.name}: {st.get('frames', 0)} frames {rate:6.1f} Hz  dropped {st.get('frames_dropped', 0)}"
                         f"  crc/bad {st.get('crc_errors', 0)}")
        err.print(f"{elapsed:7.1f} s  " + "  |  ".join(parts), highlight=False)

    stop = threading.Event()
    old = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        res = run_capture(streams, out, duration_s=duration, flush_s=flush_s, reconnect_s=reconnect_s,
                          on_progress=progress, progress_s=1.0, stop=stop)
    except CaptureError as exc:
        fail(str(exc))
    finally:
        signal.signal(signal.SIGTERM, old)
    for s, st in zip(streams, res.stats):
        console.print(f"{s.name} ({s.protocol} {s.url}): {st.get('frames', 0)} frames, dropped {st.get('frames_dropped', 0)}, "
                      f"crc/bad {st.get('crc_errors', 0)}, garbage bytes {st.get('garbage_bytes', 0)}", highlight=False)
    console.print(f"session {res.session}: {res.seconds:.1f} s, stop: {res.reason}; wrote {res.out} (raw log {res.rawlog})",
                  highlight=False)
    _note_gaps(res.out, f"session-{res.session}")
    if res.reason.startswith("port vanished"):
        err.print(f"[bold red]error:[/] {res.reason.removeprefix('port vanished: ')}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)


def _note_gaps(path, episode: str) -> None:
    """One line per stream that stalled for more than 1 s (left empty on the common clock, not bridged)."""
    from sensors.data.recording import Recording, RecordingError

    try:
        with Recording(path) as rec:
            a = rec.episode_attrs(episode)
    except (RecordingError, KeyError, OSError):
        return
    for k, g in a.items():
        if k.endswith("_gaps_s") and len(g):
            console.print(f"note: {k[:-7]}: {len(g)} stretch(es) without a sample (> 1 s, longest "
                          f"{max(float(x[1]) for x in g):.1f} s) left empty on the common clock", highlight=False)


@app.command("import")
def import_(
    sensor_log: Annotated[Path | None, typer.Argument(help="Sensor log: 'value unix_time_s' per line (with --spec: the data folder or one file).")] = None,
    force_log: Annotated[Path | None, typer.Argument(help="Load-cell log: 'force unix_time_s' per line.")] = None,
    out: Annotated[Path, typer.Option("-o", "--out", help="Recording to write (.h5).")] = Path("real.h5"),
    lupasic_dir: Annotated[Path | None, typer.Option("--dir", help="Instead of two logs: every run of a Lupasic folder (velostat_data/, futek_data/), one episode each.")] = None,
    rate: Annotated[float | None, typer.Option(help="Common clock rate in Hz (default: the sensor's rate, rounded).")] = None,
    force_units: Annotated[str, typer.Option(help="Units of the force log: N | kg | counts (counts need --calibration).")] = "N",
    calibration: Annotated[Path | None, typer.Option(help="'counts kg' pairs, e.g. futek_calibration.txt.")] = None,
    sensor_units: Annotated[str, typer.Option(help="Units of the sensor values.")] = "raw",
    family: Annotated[str, typer.Option(help="Sensor family recorded in /sensor.")] = "velostat",
    spec: Annotated[str | None, typer.Option("--spec", help="Column-log spec: a YAML file or a built-in layout (lupasic-sweep, tams); see docs/real-sensors.md.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace the -o recording if it exists.")] = False,
) -> None:
    """Import a sensor log and a load-cell log (host unix time) into a recording with source="real"."""
    from sensors.data.real_import import ImportLogError, import_runs, lupasic_pairs

    n_logs = (sensor_log is not None) + (force_log is not None)
    if spec is None and ((lupasic_dir is None and n_logs != 2) or (lupasic_dir is not None and n_logs)):
        fail("give either SENSOR_LOG FORCE_LOG or --dir FOLDER")
    if rate is not None and not (rate > 0 and rate < float("inf")):
        fail(f"--rate must be a finite number > 0 Hz (got {rate}; leave it out for the sensor's own rate)")
    if out.is_dir():
        fail(f"-o '{out}' is a folder, not a recording file")
    if out.exists() and not force:
        fail(f"'{out}' exists; add --force to replace it")
    _check_writable(out.parent if str(out.parent) else Path("."))
    if spec is not None:
        from piezotwin.cmd_real import import_with_spec

        return import_with_spec(spec, sensor_log, force_log, out, rate)
    try:
        pairs = lupasic_pairs(lupasic_dir) if lupasic_dir is not None else [(sensor_log, force_log)]
        p = import_runs(pairs, out, rate_hz=rate, force_units=force_units, calibration=calibration,
                        sensor_units=sensor_units, family=family)
    except ImportLogError as exc:
        fail(str(exc))
    from sensors.data.recording import Recording

    with Recording(p) as rec:
        for ep in rec.episode_ids:
            a = rec.episode_attrs(ep)
            console.print(f"{ep}: sensor {a['sensor_rate_hz']:.1f} Hz, force {a['force_rate_hz']:.1f} Hz -> {a['rate_hz']:g} Hz "
                          f"common clock, {a['duration_s']:.1f} s, force {a['force_min_n']:.2f} .. {a['force_max_n']:.2f} N",
                          highlight=False, soft_wrap=True)
    _print_summary(p)


@app.command()
def serve(
    source: Annotated[str, typer.Argument(help="Preset name (simulated, one episode) or a recording file.")],
    url: Annotated[str, typer.Option(help="socket://HOST:PORT (listen; port 0 = any), pty[:LINK], or a port URL to write to.")],
    protocol: Annotated[str, typer.Option(help=_PROTO_HELP)] = "frames",
    rate: Annotated[float | None, typer.Option(help="Samples per second (default: the source's rate).")] = None,
    channel: Annotated[str | None, typer.Option(help="Channel to serve (default: resistance_measured / adc).")] = None,
    set_: Annotated[list[str] | None, typer.Option("--set", help="Override a preset field (repeatable).")] = None,
    episode: Annotated[int, typer.Option(help="Episode index of the preset to simulate.")] = 0,
    drop_bytes: Annotated[float, typer.Option(help="Fault: probability that a byte is dropped.")] = 0.0,
    bit_flips: Annotated[float, typer.Option(help="Fault: probability that a byte gets one bit flipped.")] = 0.0,
    stall_s: Annotated[float, typer.Option(help="Fault: go quiet this long ...")] = 0.0,
    stall_every_s: Annotated[float, typer.Option(help="... every this many seconds.")] = 2.0,
    disconnect_every_s: Annotated[float, typer.Option(help="Fault: drop the link this often (s).")] = 0.0,
    fault_seed: Annotated[int, typer.Option(help="Seed of the fault draws.")] = 0,
    duration: Annotated[float | None, typer.Option(help="Stop after this many seconds.")] = None,
    frames: Annotated[int | None, typer.Option(help="Stop after this many samples.")] = None,
    baudrate: Annotated[int, typer.Option(help="Baud rate (real ports).")] = 115200,
    fault_log: Annotated[Path | None, typer.Option(help="Write what was sent, corrupted or unsent (JSON) here.")] = None,
    start_delay: Annotated[float, typer.Option(help="Wait this long (s) after a client appears before streaming.")] = 0.0,
    client_timeout: Annotated[float, typer.Option(help="Stop when no client has come for this long (s), at the start or after a client left.")] = 30.0,
) -> None:
    """Play a simulated sensor as a real board would, over text, poll or frames, with injectable faults.

    Over socket:// it serves one client at a time, for as many clients as come (a restarted capture gets
    the stream again, from the next sample on); each client's arrival and departure is printed."""
    from sensors.serial.board import DeviceError, Faults, check_rate
    from sensors.serial.board import serve as run_serve
    from simulate.generation.board_source import load_source

    _check_protocol(protocol, "--protocol")
    if duration is not None and not duration > 0:
        fail(f"--duration must be > 0 s, got {duration:g}")
    if frames is not None and frames < 1:
        fail(f"--frames must be >= 1, got {frames}")
    if not 0 <= start_delay <= 60:
        fail(f"--start-delay must be in [0, 60] s, got {start_delay:g}")
    if not client_timeout > 0:
        fail(f"--client-timeout must be > 0 s, got {client_timeout:g}")
    try:
        check_rate(rate)
        faults = Faults(drop_bytes, bit_flips, stall_s, stall_every_s, disconnect_every_s, fault_seed)
        src = load_source(source, channel, set_, seed=episode)
    except DeviceError as exc:
        fail(str(exc))
    stop = threading.Event()
    old = signal.signal(signal.SIGTERM, lambda *_: stop.set())

    def ready(u: str) -> None:
        console.print(f"serving {src.channel} ({src.units}, {src.values.shape[1]} value(s), {len(src.values)} samples) "
                      f"from {src.origin} on {u} as {protocol} at {rate or src.rate_hz:g} Hz", highlight=False)
        sys.stdout.flush()

    def event(msg: str) -> None:
        console.print(msg, highlight=False)
        sys.stdout.flush()

    try:
        log = run_serve(src, url, protocol, rate_hz=rate, faults=faults, duration_s=duration, max_frames=frames,
                        baudrate=baudrate, on_ready=ready, should_stop=stop.is_set,
                        start_delay_s=start_delay, client_timeout_s=client_timeout, on_event=event)
    except DeviceError as exc:
        fail(str(exc))
    except KeyboardInterrupt:
        return
    finally:
        signal.signal(signal.SIGTERM, old)
    if fault_log:
        fault_log.write_text(log.to_json())
    console.print(f"sent {len(log.sent)} intact, {len(log.corrupted)} corrupted, {len(log.unsent)} unsent "
                  f"to {log.clients} client(s); {log.disconnects} disconnects, {log.stalls} stalls", highlight=False)

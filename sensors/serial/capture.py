"""Capture from serial boards: an append-only raw log (crash-safe) and a recording built from it.

A capture writes ``<out>.rawlog`` while it runs: every read from every port is one record
``type u8 | stream u8 | flags u16 | length u32 | host_monotonic_ns i64 | payload | crc32`` (CRC-32 of
header and payload), after the magic line ``PZTRAWLOG1``. The log is flushed and fsynced every
``flush_s`` (<= 1 s), so a crash or an unplugged cable loses at most that much; a torn last record is
dropped on reading and cut off before appending. A restart appends a new SESSION record instead of
overwriting. Records: SESSION (JSON: streams, host/unix start times), RAW (bytes read), POLL (the host
wrote a poll), EVENT (JSON: disconnect, reconnect, stop reason), TIMEOUT (the host gave up waiting for
the reply to its last poll).

Poll protocol: the reply to a poll is what arrives within ``reply_timeout_s`` of it; after a timeout
the host writes TIMEOUT and, before polling again, waits up to ``late_reply_s`` for the rest of the late
reply. Bytes read after a TIMEOUT are kept in the raw log but never decoded as a reply, and whatever is
waiting when the host is about to poll is read before the POLL record (discarded as an overlong reply),
so a late reply is not taken for the next poll's (only one later than both windows can be).

The recording ``<out>`` (HDF5, source="real", sensors.data.recording schema) is built from the log by
decoding it again (so a parser fix can re-decode an old capture: ``build_recording``). It is written
atomically at the end of a capture, when a port vanishes, on Ctrl-C, and by ``capture --rebuild``.
One episode per session, ``session-<k>``; stream 0 is the time base:

* ``time`` (s, host monotonic since the session start), ``host_time_ns``, ``seq``, ``t_device_us``;
* ``<name>`` (time, channel): each stream's values; streams other than 0 are linearly interpolated onto
  stream 0's host times (NaN outside their span) and also kept natively as ``<name>_native``,
  ``<name>_host_time_ns``, ``<name>_seq`` on their own ``<name>_sample`` axis;
* ``<name>_raw`` (uint8) and ``<name>_raw_reads`` (host_ns, end offset, kind) for every stream;
* episode attrs ``port``, ``baudrate``, ``protocol``, ``frames_dropped``, ``crc_errors`` (stream 0) and
  ``<name>_<attr>`` for every stream.
"""

from __future__ import annotations

import json
import os
import queue
import select
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sensors.data.resample import MAX_GAP_S
from sensors.serial.codec import PROTOCOLS, make_decoder

MAGIC = b"PZTRAWLOG1\n"
SESSION, RAW, POLL, EVENT, TIMEOUT = 1, 2, 3, 4, 5
_REC = struct.Struct("<BBHIq")
_CRC = struct.Struct("<I")
MAX_RECORD = 1 << 24

__all__ = [
    "CaptureError",
    "RawLog",
    "StreamSpec",
    "build_recording",
    "capture",
    "decode_log",
    "rawlog_path",
    "read_records",
]


class CaptureError(RuntimeError):
    """A capture problem with a one-line message (bad URL, port vanished, unreadable log)."""


@dataclass
class StreamSpec:
    url: str
    protocol: str
    name: str = "s0"
    baudrate: int = 115200
    n_values: int | None = None  # poll: values per reply (default 1)
    units: str = "raw"
    poll_hz: float | None = None  # poll: cap on the polling rate (None = as fast as replies come)
    reply_timeout_s: float = 0.1  # poll: a reply not complete by then is dropped
    late_reply_s: float = 1.0  # poll: after a timeout, wait up to this long for the late reply before polling again

    def __post_init__(self) -> None:
        if self.protocol not in PROTOCOLS:
            raise CaptureError(f"unknown protocol '{self.protocol}' (allowed: {', '.join(PROTOCOLS)})")


def rawlog_path(out: str | os.PathLike) -> Path:
    out = Path(out)
    return out.with_name(out.name + ".rawlog")


# --------------------------------------------------------------------------- the raw log


def read_records(path: str | os.PathLike) -> Iterator[tuple[int, int, int, bytes, int]]:
    """Yield (type, stream, host_ns, payload, end_offset) up to the first torn or corrupt record."""
    path = Path(path)
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise CaptureError(f"{path}: not a piezotwin raw log (bad magic)")
        off = len(MAGIC)
        while True:
            head = f.read(_REC.size)
            if len(head) < _REC.size:
                return
            typ, stream, _flags, n, host_ns = _REC.unpack(head)
            if n > MAX_RECORD:
                return
            payload = f.read(n)
            tail = f.read(_CRC.size)
            if len(payload) < n or len(tail) < _CRC.size:
                return
            if _CRC.unpack(tail)[0] != zlib.crc32(head + payload):
                return
            off += _REC.size + n + _CRC.size
            yield typ, stream, host_ns, payload, off


class RawLog:
    """Append-only writer; reopening an existing log cuts a torn tail and appends."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        end = 0
        if self.path.exists() and self.path.stat().st_size > 0:
            for *_, end in read_records(self.path):
                pass
            end = max(end, len(MAGIC))
            self._f = open(self.path, "r+b")
            self._f.truncate(end)
            self._f.seek(end)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._f = open(self.path, "wb")
            self._f.write(MAGIC)
        self.n_sessions = sum(1 for r in read_records(self.path) if r[0] == SESSION) if end else 0

    def write(self, typ: int, stream: int, host_ns: int, payload: bytes = b"") -> None:
        head = _REC.pack(typ, stream, 0, len(payload), host_ns)
        self._f.write(head + payload + _CRC.pack(zlib.crc32(head + payload)))

    def flush(self) -> None:
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        if not self._f.closed:
            self.flush()
            self._f.close()


# --------------------------------------------------------------------------- decoding a log


@dataclass
class _StreamData:
    spec: dict
    host_ns: list[int] = field(default_factory=list)
    seq: list[int] = field(default_factory=list)
    t_dev: list[int] = field(default_factory=list)
    values: list[tuple] = field(default_factory=list)
    raw: bytearray = field(default_factory=bytearray)
    reads: list[tuple[int, int, int]] = field(default_factory=list)
    stats: dict = field(default_factory=dict)


@dataclass
class _Session:
    info: dict
    streams: list[_StreamData]
    events: list[dict] = field(default_factory=list)


class _Replayer:
    """Feeds log records to decoders; used live (progress) and offline (building the recording)."""

    def __init__(self, keep: bool = True):
        self.sessions: list[_Session] = []
        self.keep = keep
        self._dec: list = []

    def record(self, typ: int, stream: int, host_ns: int, payload: bytes) -> None:
        if typ == SESSION:
            info = json.loads(payload)
            streams = [_StreamData(s) for s in info["streams"]]
            self.sessions.append(_Session(info, streams))
            self._dec = [make_decoder(s["protocol"], s.get("n_values")) for s in info["streams"]]
            return
        if not self.sessions or stream >= len(self._dec):
            return
        sess = self.sessions[-1]
        sd, dec = sess.streams[stream], self._dec[stream]
        if typ == POLL:
            dec.poll()
        elif typ == TIMEOUT:
            dec.timeout()
        elif typ == RAW:
            if self.keep:
                sd.raw += payload
            for fr in dec.feed(payload):
                if self.keep:
                    sd.host_ns.append(host_ns)
                    sd.seq.append(fr.seq)
                    sd.t_dev.append(fr.t_device_us)
                    sd.values.append(fr.values)
        elif typ == EVENT:
            ev = json.loads(payload)
            ev["host_ns"] = host_ns
            sess.events.append(ev)
        if self.keep and typ in (RAW, POLL, TIMEOUT):
            sd.reads.append((host_ns, len(sd.raw), typ))
        sd.stats = dec.stats()

    def stats(self) -> list[dict]:
        return [s.stats for s in self.sessions[-1].streams] if self.sessions else []


def decode_log(path: str | os.PathLike) -> list[_Session]:
    rp = _Replayer()
    for typ, stream, host_ns, payload, _ in read_records(path):
        rp.record(typ, stream, host_ns, payload)
    return rp.sessions


def _values_array(sd: _StreamData) -> np.ndarray:
    if not sd.values:
        n = sd.spec.get("n_values") or 1
        return np.zeros((0, n), np.float32)
    width = max(len(v) for v in sd.values)
    arr = np.full((len(sd.values), width), np.nan, np.float32)
    for i, v in enumerate(sd.values):
        arr[i, : len(v)] = v
    return arr


def interp_onto(t_new: np.ndarray, t: np.ndarray, y: np.ndarray, max_gap_s: float | None = None) -> np.ndarray:
    """Linear interpolation of y[t] (time along axis 0) onto t_new; NaN outside t's span, and with ``max_gap_s``
    NaN inside a stretch of more than max_gap_s between two samples (a stalled stream: a line drawn across it would
    be made-up data)."""
    y = np.asarray(y, np.float64).reshape(len(t), -1)
    out = np.full((len(t_new), y.shape[1]), np.nan)
    if len(t) == 0:
        return out
    order = np.argsort(t, kind="stable")
    t, y = np.asarray(t, np.float64)[order], y[order]
    inside = (t_new >= t[0]) & (t_new <= t[-1])
    if max_gap_s is not None and len(t) > 1:
        k = np.clip(np.searchsorted(t, t_new, side="right") - 1, 0, len(t) - 2)
        inside &= ~(np.diff(t)[k] > max_gap_s) | np.isin(t_new, t)
    for c in range(y.shape[1]):
        out[inside, c] = np.interp(t_new[inside], t, y[:, c])
    return out


def gaps_of(t: np.ndarray, max_gap_s: float) -> list[list[float]]:
    """[[start_s, length_s], ...]: the stretches of more than max_gap_s between consecutive samples of t."""
    t = np.sort(np.asarray(t, np.float64))
    d = np.diff(t)
    return [[float(t[i]), float(d[i])] for i in np.flatnonzero(d > max_gap_s)]


def build_recording(log: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Decode a raw log and write the recording ``out`` atomically (see the module docstring)."""
    from sensors.data.recording import Channel, write_recording

    log, out = Path(log), Path(out)
    if not log.exists():
        raise CaptureError(f"{log}: no raw log to build from")
    sessions = decode_log(log)
    if not sessions:
        raise CaptureError(f"{log}: the raw log holds no session")
    episodes: dict[str, dict[str, Channel]] = {}
    ep_attrs: dict[str, dict[str, Any]] = {}
    for k, sess in enumerate(sessions):
        t0 = sess.info["start_host_ns"]
        ref = sess.streams[0]
        h0 = np.asarray(ref.host_ns, np.int64)
        t_ref = (h0 - t0) / 1e9
        ch: dict[str, Channel] = {
            "time": Channel(t_ref, "s", ("time",), f"host monotonic time since the session start (stream {ref.spec['name']})"),
            "host_time_ns": Channel(h0, "ns", ("time",), "host CLOCK_MONOTONIC when the sample's last byte was read"),
            "seq": Channel(np.asarray(ref.seq, np.int64), "1", ("time",), "frame sequence number (-1: none)"),
            "t_device_us": Channel(np.asarray(ref.t_dev, np.int64), "us", ("time",), "device clock (-1: none)"),
        }
        attrs: dict[str, Any] = {
            "session": k,
            "start_unix_s": sess.info.get("start_unix_s"),
            "start_host_ns": t0,
            "streams": [s.spec for s in sess.streams],
            "events": sess.events,
        }
        for i, sd in enumerate(sess.streams):
            name, units = sd.spec["name"], sd.spec.get("units", "raw")
            vals = _values_array(sd)
            hn = np.asarray(sd.host_ns, np.int64)
            if i == 0:
                ch[name] = Channel(vals, units, ("time", "channel"), f"{sd.spec['protocol']} stream from {sd.spec['url']}")
            else:
                ch[name] = Channel(
                    interp_onto(t_ref, (hn - t0) / 1e9, vals, MAX_GAP_S).astype(np.float32), units, ("time", "channel"),
                    f"{sd.spec['protocol']} stream from {sd.spec['url']}, linearly interpolated onto stream 0's times",
                )
                ax = f"{name}_sample"
                if gaps := gaps_of((hn - t0) / 1e9, MAX_GAP_S):  # left empty on stream 0's clock, not bridged
                    attrs[f"{name}_gaps_s"] = gaps
                ch[f"{name}_native"] = Channel(vals, units, (ax, "channel"), "values as received")
                ch[f"{name}_host_time_ns"] = Channel(hn, "ns", (ax,), "host CLOCK_MONOTONIC at arrival")
                ch[f"{name}_seq"] = Channel(np.asarray(sd.seq, np.int64), "1", (ax,), "sequence number (-1: none)")
            ch[f"{name}_raw"] = Channel(np.frombuffer(bytes(sd.raw), np.uint8), "byte", (f"{name}_byte",), "raw bytes as read")
            reads = np.asarray(sd.reads, np.int64).reshape(-1, 3)
            ch[f"{name}_raw_reads"] = Channel(
                reads, "1", (f"{name}_read", "field"), "per read: host_ns, end offset into _raw, kind (2 read, 3 poll, 5 reply timeout)"
            )
            st = dict(sd.stats) or {"frames": 0, "crc_errors": 0, "frames_dropped": 0, "garbage_bytes": 0, "bytes": 0}
            per = {"port": sd.spec["url"], "baudrate": sd.spec["baudrate"], "protocol": sd.spec["protocol"],
                   "units": units, **st}
            if len(hn) >= 2:
                per["rate_hz"] = (len(hn) - 1) / ((hn[-1] - hn[0]) / 1e9) if hn[-1] > hn[0] else 0.0
            attrs.update({f"{name}_{a}": v for a, v in per.items()})
            if i == 0:
                attrs.update({a: per[a] for a in ("port", "baudrate", "protocol", "frames_dropped", "crc_errors")})
        episodes[f"session-{k}"] = ch
        ep_attrs[f"session-{k}"] = attrs
    first = sessions[0]
    cfg = {"capture": {"streams": first.info["streams"], "rawlog": log.name}}
    rate = ep_attrs["session-0"].get(f"{first.streams[0].spec['name']}_rate_hz")
    return write_recording(
        out,
        episodes,
        source="real",
        config_json=json.dumps(cfg, sort_keys=True),
        root_seed=None,
        shard_index=0,
        sensor_attrs={"family": "unknown", "sample_rate_hz": rate, "streams": first.info["streams"]},
        episode_attrs=ep_attrs,
        extra_attrs={"rawlog": log.name, "n_sessions": len(sessions)},
    )


# --------------------------------------------------------------------------- capturing


POLL_READ_TIMEOUT_S = 0.05  # poll: a read waits this long for more of the reply
WAIT_S = 0.05  # streaming: how long a reader waits for data before checking whether to stop


def open_port(spec: StreamSpec, timeout: float | None = None):
    """Open a stream's port; one-line CaptureError if it cannot be opened.

    Streaming framings (``text``, ``frames``) open the port non-blocking (timeout 0: a read returns what
    is there, for every URL kind; ``_read_available`` does the waiting), ``poll`` with a read timeout of
    POLL_READ_TIMEOUT_S. A ``socket://`` port keeps what arrived while it was being opened: pyserial
    clears its input at the end of ``open()``, which on a fresh connection throws away the first bytes
    the board sent (the first frame; issue 17, item 4), not stale ones."""
    import serial

    if timeout is None:
        timeout = POLL_READ_TIMEOUT_S if spec.protocol == "poll" else 0.0
    try:
        ser = serial.serial_for_url(spec.url, baudrate=spec.baudrate, timeout=timeout, write_timeout=1.0,
                                    do_not_open=True)
        if spec.url.startswith("socket://"):
            ser.reset_input_buffer = lambda: None  # only for open(): a new connection has no stale input
            try:
                ser.open()
            finally:
                del ser.reset_input_buffer
        else:
            ser.open()
        return ser
    except (serial.SerialException, ValueError, OSError) as exc:
        raise CaptureError(f"cannot open port '{spec.url}': {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None


def _read_available(ser, wait_s: float = WAIT_S) -> bytes:
    """What the port has now, in one block (a non-blocking port); if nothing, wait up to ``wait_s`` for data.

    Waits on the port's file descriptor where it has one (a serial device, a pty, ``socket://``), else
    (``loop://``, other URL handlers) polls every millisecond. Raises what the port raises on a lost link."""
    b = ser.read(65536)
    if b:
        return b
    try:
        fd = ser.fileno()
    except Exception:  # noqa: BLE001 - URL handlers without a file descriptor
        fd = None
    if fd is None:
        time.sleep(0.001)
    else:
        select.select([fd], [], [], wait_s)
    return ser.read(65536)


def _read_reply(i: int, ser, size: int, timeout_s: float, q: queue.Queue, stop: threading.Event) -> int:
    """Read up to ``size`` bytes for at most ``timeout_s`` (what is already there is read even when the
    thread wakes late); each read goes to the queue. Returns the number of bytes read."""
    got, deadline = 0, time.monotonic() + timeout_s
    while got < size and not stop.is_set():
        b = ser.read(size - got)
        if b:
            got += len(b)
            q.put((RAW, i, time.monotonic_ns(), b))
        if time.monotonic() >= deadline:
            break
    return got


def _reader(i: int, spec: StreamSpec, ser, q: queue.Queue, stop: threading.Event) -> None:
    """Reads one port into the queue as (type, stream, host_ns, payload); ('gone', i, ns, msg) on loss."""
    import serial

    try:
        if spec.protocol == "poll":
            size = 4 * (spec.n_values or 1)
            period = 1.0 / spec.poll_hz if spec.poll_hz else 0.0
            next_t = time.monotonic()
            while not stop.is_set():
                if period:
                    now = time.monotonic()
                    if now < next_t:
                        time.sleep(next_t - now)
                    next_t = max(next_t + period, time.monotonic() - period)
                stale = bytearray()  # an overlong or very late reply: logged before the poll, so not its reply
                while n := ser.in_waiting:
                    stale += ser.read(n)
                if stale:
                    q.put((RAW, i, time.monotonic_ns(), bytes(stale)))
                q.put((POLL, i, time.monotonic_ns(), b""))
                ser.write(b"\n")
                got = _read_reply(i, ser, size, spec.reply_timeout_s, q, stop)
                if got < size and not stop.is_set():
                    # no reply in time: the poll is dropped; its late reply, if it comes, is logged after
                    # TIMEOUT (never decoded) and waited for, so that it is not read as the next poll's
                    q.put((TIMEOUT, i, time.monotonic_ns(), b""))
                    _read_reply(i, ser, size - got, spec.late_reply_s, q, stop)
        else:
            while not stop.is_set():
                b = _read_available(ser)
                if b:
                    q.put((RAW, i, time.monotonic_ns(), b))
    except (serial.SerialException, OSError) as exc:
        if not stop.is_set():
            q.put(("gone", i, time.monotonic_ns(), str(exc).splitlines()[0] if str(exc) else type(exc).__name__))


@dataclass
class CaptureResult:
    out: Path
    rawlog: Path
    session: int
    stats: list[dict]
    reason: str  # "duration" | "interrupted" | "port vanished: ..."
    seconds: float


def capture(
    streams: list[StreamSpec],
    out: str | os.PathLike,
    *,
    duration_s: float | None = None,
    flush_s: float = 0.5,
    reconnect_s: float = 0.0,
    on_progress: Callable[[list[dict], float], None] | None = None,
    progress_s: float = 0.5,
    stop: threading.Event | None = None,
) -> CaptureResult:
    """Capture until duration, ``stop`` is set, Ctrl-C, or a port vanishes (and stays gone longer than
    ``reconnect_s``); then build the recording. The raw log is appended to if it exists."""
    if not streams:
        raise CaptureError("no stream to capture")
    if not 0 < flush_s <= 1.0:
        raise CaptureError(f"flush interval must be in (0, 1] s, got {flush_s}")
    names = [s.name for s in streams]
    if len(set(names)) != len(names):
        raise CaptureError(f"stream names must differ, got {names}")
    out = Path(out)
    stop = stop or threading.Event()
    ports: list = []
    try:
        for s in streams:
            ports.append(open_port(s))
    except CaptureError:
        for p in ports:
            p.close()
        raise
    log = RawLog(rawlog_path(out))
    session = log.n_sessions
    start_ns = time.monotonic_ns()
    info = {"streams": [asdict(s) for s in streams], "start_host_ns": start_ns, "start_unix_s": time.time()}
    q: queue.Queue = queue.Queue()
    live = _Replayer(keep=False)
    rec = (SESSION, 0, start_ns, json.dumps(info).encode())
    log.write(*rec)
    live.record(*rec)
    log.flush()
    threads: list[threading.Thread | None] = [None] * len(streams)

    def start(i: int) -> None:
        t = threading.Thread(target=_reader, args=(i, streams[i], ports[i], q, stop), daemon=True)
        threads[i] = t
        t.start()

    for i in range(len(streams)):
        start(i)
    reason = "interrupted"
    t_start = time.monotonic()
    last_flush = last_prog = t_start
    gone: dict[int, tuple[float, str]] = {}
    try:
        while True:
            now = time.monotonic()
            if duration_s is not None and now - t_start >= duration_s:
                reason = "duration"
                break
            if stop.is_set():
                break
            items = []  # what the readers handed over: one item (waited for), then what else is queued
            try:
                items.append(q.get(timeout=0.05))
                while len(items) < 1000:
                    items.append(q.get_nowait())
            except queue.Empty:
                pass
            for typ, i, host_ns, payload in items:
                if typ == "gone":
                    ev = {"event": "disconnected", "stream": i, "message": payload}
                    log.write(EVENT, i, host_ns, json.dumps(ev).encode())
                    log.flush()
                    gone[i] = (time.monotonic(), payload)
                    try:
                        ports[i].close()
                    except Exception:  # noqa: BLE001
                        pass
                else:
                    log.write(typ, i, host_ns, payload)
                    live.record(typ, i, host_ns, payload)
            for i, (since, msg) in list(gone.items()):
                try:
                    ports[i] = open_port(streams[i])
                except CaptureError:
                    if time.monotonic() - since >= reconnect_s:
                        raise CaptureError(
                            f"port '{streams[i].url}' vanished ({msg}); recording valid up to the last flush"
                        ) from None
                    continue
                del gone[i]
                log.write(EVENT, i, time.monotonic_ns(), json.dumps({"event": "reconnected", "stream": i}).encode())
                start(i)
            now = time.monotonic()
            if now - last_flush >= flush_s:
                log.flush()
                last_flush = now
            if on_progress and now - last_prog >= progress_s:
                on_progress(live.stats(), now - t_start)
                last_prog = now
    except CaptureError as exc:
        reason = f"port vanished: {exc}"
    except KeyboardInterrupt:
        reason = "interrupted"
    finally:
        stop.set()
        for t in threads:
            if t is not None:
                t.join(timeout=1.0)
        while True:  # what the readers handed over before stopping
            try:
                typ, i, host_ns, payload = q.get_nowait()
            except queue.Empty:
                break
            if typ != "gone":
                log.write(typ, i, host_ns, payload)
                live.record(typ, i, host_ns, payload)
        log.write(EVENT, 0, time.monotonic_ns(), json.dumps({"event": "stop", "reason": reason}).encode())
        log.close()
        for p in ports:
            try:
                p.close()
            except Exception:  # noqa: BLE001
                pass
    build_recording(log.path, out)
    return CaptureResult(out, log.path, session, live.stats(), reason, time.monotonic() - t_start)

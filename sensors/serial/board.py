"""A virtual sensor board: plays a simulated (or recorded) channel over a serial framing, with faults.

Where it serves (``url``):

* ``socket://HOST:PORT`` or ``tcp://HOST:PORT``: listens (PORT 0 picks a free one) and streams to one
  client at a time; a capture connects with ``socket://HOST:PORT``. Streaming starts when a client
  connects, as a board behind a serial-to-TCP bridge that powers up with the link, and pauses while
  no client is connected: when a client disconnects, the board waits for the next one (up to
  ``client_timeout_s``) and goes on with the next sample, so a restarted capture gets the stream again.
* ``pty`` or ``pty:LINK``: creates a pseudo-terminal (raw mode) and serves on its master; the capture
  opens the slave path (printed, and symlinked at LINK when given, re-pointed after a disconnect).
* anything else: opened with ``serial.serial_for_url`` and written to (a real port, a null modem).

Streaming framings (``text``, ``frames``) send sample k at ``k / rate_hz`` after the start, looping
over the data; ``poll`` answers each ``\\n`` with the sample of the current time. Frames carry
``seq = k mod 65536`` and ``t_device_us = k * 1e6 / rate_hz``.

Faults (seeded): ``drop_bytes`` (probability per byte), ``bit_flips`` (probability per byte of one
flipped bit), ``stall_s`` every ``stall_every_s`` (the board goes quiet, then resumes with the next
sample: no sample is skipped), ``disconnect_every_s`` (the link drops and comes back). The fault log
(JSON) lists, by sample index k, what was sent intact, corrupted, or not sent because no one was
connected, so tests can check that every intact frame arrived and every corrupted one was counted.
"""

from __future__ import annotations

import json
import os
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sensors.serial.codec import PROTOCOLS, encode_frame, encode_poll_reply, encode_text

MEASURED = ("resistance_measured", "adc", "voltage", "resistance")


class DeviceError(RuntimeError):
    """A one-line problem with the virtual device's source or url."""


@dataclass
class Faults:
    drop_bytes: float = 0.0
    bit_flips: float = 0.0
    stall_s: float = 0.0
    stall_every_s: float = 2.0
    disconnect_every_s: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("drop_bytes", "bit_flips"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise DeviceError(f"--{name.replace('_', '-')} is a probability in [0, 1], got {p}")
        for name in ("stall_s", "stall_every_s", "disconnect_every_s"):
            if getattr(self, name) < 0:
                raise DeviceError(f"--{name.replace('_', '-')} must be >= 0")

    def apply(self, data: bytes, rng: np.random.Generator) -> bytes:
        if not (self.drop_bytes or self.bit_flips):
            return data
        a = np.frombuffer(data, np.uint8).copy()
        if self.bit_flips:
            hit = rng.random(len(a)) < self.bit_flips
            a[hit] ^= (1 << rng.integers(0, 8, hit.sum())).astype(np.uint8)
        if self.drop_bytes:
            a = a[rng.random(len(a)) >= self.drop_bytes]
        return a.tobytes()


@dataclass
class Source:
    values: np.ndarray  # (T, C) float32
    rate_hz: float
    units: str
    channel: str
    origin: str


def load_recording_source(path: str | Path, channel: str | None = None) -> Source:
    """A recording file's first episode, one measured channel (the first of MEASURED it has unless named)."""
    p = Path(path)
    from sensors.data.recording import Recording, RecordingError

    try:
        with Recording(p) as rec:
            ep = rec.episode_ids[0]
            names = rec.channels(ep)
            ch = channel or next((c for c in MEASURED if c in names), None)
            if ch is None or ch not in names:
                raise DeviceError(f"{p}: no channel {channel or 'to serve'!r} (has {', '.join(names)})")
            t = rec.read(ep, "time") if "time" in names else None
            vals = rec.read(ep, ch)
            units = rec.units(ep, ch)
    except (RecordingError, OSError, KeyError) as exc:
        raise DeviceError(f"{p}: {str(exc).splitlines()[0]}") from None
    rate = 1.0 / float(np.median(np.diff(t))) if t is not None and len(t) > 1 else 100.0
    return Source(as_2d(vals), rate, units, ch, str(p))


def as_2d(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, np.float32)
    return a.reshape(len(a), -1)


# --------------------------------------------------------------------------- transports


class _Transport:
    url = ""

    def wait_client(self, timeout: float) -> bool:
        return True

    @property
    def connected(self) -> bool:
        """Whether a client is connected (always, for transports that cannot tell)."""
        return True

    @property
    def peer(self) -> str:
        """Who is connected, in words (for the log)."""
        return self.url

    def write(self, data: bytes) -> bool:
        raise NotImplementedError

    def read(self) -> bytes:
        return b""

    def disconnect(self) -> None:
        pass

    def linger(self, timeout: float = 1.0) -> None:
        pass

    def close(self) -> None:
        pass


class _TcpTransport(_Transport):
    def __init__(self, host: str, port: int):
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.srv.bind((host, port))
        except OSError as exc:
            raise DeviceError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
        self.srv.listen(1)
        self.url = f"socket://{host}:{self.srv.getsockname()[1]}"
        self.conn: socket.socket | None = None
        self._peer = "nobody"

    def wait_client(self, timeout: float) -> bool:
        if self.conn is not None:
            return True
        r, _, _ = select.select([self.srv], [], [], timeout)
        if r:
            self.conn, addr = self.srv.accept()
            self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._peer = f"{addr[0]}:{addr[1]}"
        return self.conn is not None

    @property
    def connected(self) -> bool:
        return self.conn is not None

    @property
    def peer(self) -> str:
        return self._peer if self.conn is not None else "nobody"

    def write(self, data: bytes) -> bool:
        if self.conn is None:
            return False
        try:
            self.conn.sendall(data)
            return True
        except OSError:
            self.disconnect()
            return False

    def read(self) -> bytes:
        if self.conn is None:
            return b""
        r, _, _ = select.select([self.conn], [], [], 0)
        if not r:
            return b""
        try:
            b = self.conn.recv(4096)
        except OSError:
            b = b""
        if not b:
            self.disconnect()
        return b

    def disconnect(self) -> None:
        if self.conn is not None:
            try:
                self.conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self.conn.close()
            self.conn = None

    def close(self) -> None:
        self.disconnect()
        self.srv.close()


class _PtyTransport(_Transport):
    def __init__(self, link: str | None):
        self.link = Path(link) if link else None
        self._open()

    def _open(self) -> None:
        import tty

        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.url = os.ttyname(self.slave)
        if self.link:
            tmp = self.link.with_name(self.link.name + ".tmp")
            if tmp.is_symlink() or tmp.exists():
                tmp.unlink()
            os.symlink(self.url, tmp)
            os.replace(tmp, self.link)

    def write(self, data: bytes) -> bool:
        view = memoryview(data)
        deadline = time.monotonic() + 0.5
        while view:
            _, w, _ = select.select([], [self.master], [], max(0.0, deadline - time.monotonic()))
            if not w:
                return False  # no one reads: the bytes are lost, as on a real line
            n = os.write(self.master, view)
            view = view[n:]
        return True

    def read(self) -> bytes:
        r, _, _ = select.select([self.master], [], [], 0)
        if not r:
            return b""
        try:
            return os.read(self.master, 4096)
        except OSError:
            return b""

    def disconnect(self) -> None:
        self.close()
        self._open()

    def linger(self, timeout: float = 1.0) -> None:
        """Wait until the host has read what was written (closing the master discards it)."""
        import fcntl
        import termios

        buf = bytearray(4)
        time.sleep(0.1)  # the pty moves bytes from master to slave asynchronously
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                fcntl.ioctl(self.slave, termios.FIONREAD, buf)
            except OSError:
                return
            if int.from_bytes(buf, "little") == 0:
                return
            time.sleep(0.01)

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


class _SerialTransport(_Transport):
    def __init__(self, url: str, baudrate: int):
        import serial

        try:
            self.ser = serial.serial_for_url(url, baudrate=baudrate, timeout=0, write_timeout=0.5)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise DeviceError(f"cannot open '{url}': {str(exc).splitlines()[0]}") from None
        self.url = url

    def write(self, data: bytes) -> bool:
        import serial

        try:
            self.ser.write(data)
            return True
        except serial.SerialTimeoutException:
            return False

    def read(self) -> bytes:
        return self.ser.read(4096)

    def close(self) -> None:
        self.ser.close()


def open_transport(url: str, baudrate: int = 115200) -> _Transport:
    if url.startswith(("socket://", "tcp://")):
        hostport = url.split("://", 1)[1].split("?", 1)[0]
        host, _, port = hostport.rpartition(":")
        try:
            return _TcpTransport(host or "127.0.0.1", int(port))
        except ValueError:
            raise DeviceError(f"bad url '{url}': expected socket://HOST:PORT") from None
    if url == "pty" or url.startswith("pty:"):
        return _PtyTransport(url[4:] or None)
    return _SerialTransport(url, baudrate)


# --------------------------------------------------------------------------- serving


MAX_RATE_HZ = 100_000.0  # samples per second a virtual board may be asked for


@dataclass
class ServeLog:
    url: str = ""
    sent: list[int] = field(default_factory=list)  # sample index k, written intact
    corrupted: list[int] = field(default_factory=list)  # written with a fault applied
    unsent: list[int] = field(default_factory=list)  # no client / buffer full
    polls: int = 0
    disconnects: int = 0  # links dropped by the disconnect fault
    stalls: int = 0
    clients: int = 0  # clients served (one at a time)
    started_monotonic_s: float | None = None  # host time.monotonic() when sample 0 became due

    def to_json(self) -> str:
        return json.dumps(self.__dict__)


def serve(
    src: Source,
    url: str,
    protocol: str,
    *,
    rate_hz: float | None = None,
    faults: Faults | None = None,
    duration_s: float | None = None,
    max_frames: int | None = None,
    baudrate: int = 115200,
    on_ready: Callable[[str], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    client_timeout_s: float = 30.0,
    start_delay_s: float = 0.0,
    on_event: Callable[[str], None] | None = None,
) -> ServeLog:
    """Serve ``src`` until duration, max_frames or should_stop(); returns what was sent.

    Over ``socket://`` one client is served at a time, for as many clients as come: when one disconnects
    the board pauses and waits (``client_timeout_s`` at most, then it stops) for the next, which gets the
    stream from the next sample on. ``on_event`` gets a line for each client that comes or goes."""
    if protocol not in PROTOCOLS:
        raise DeviceError(f"unknown protocol '{protocol}' (allowed: {', '.join(PROTOCOLS)})")
    check_rate(rate_hz)
    rate = float(rate_hz if rate_hz is not None else src.rate_hz)
    check_rate(rate)
    faults = faults or Faults()
    rng = np.random.default_rng(faults.seed)
    tr = open_transport(url, baudrate)
    log = ServeLog(url=tr.url)
    say = on_event or (lambda _msg: None)
    if on_ready:
        on_ready(tr.url)
    T = len(src.values)
    t0 = float("inf")  # set when the first client connects: the duration runs from then on

    def over(now: float, k: int) -> bool:
        return ((duration_s is not None and now - t0 >= duration_s) or (max_frames is not None and k >= max_frames)
                or bool(should_stop and should_stop()))

    def next_client(k: int) -> bool:
        """Wait for a client (stop, duration and client_timeout_s end the wait); False if none came."""
        deadline = time.monotonic() + client_timeout_s
        while not tr.wait_client(min(0.1, max(0.0, deadline - time.monotonic()))):
            if over(time.monotonic(), k):
                return False
            if time.monotonic() >= deadline:
                say(f"no client within {client_timeout_s:g} s: stopping")
                return False
        log.clients += 1
        say(f"client {log.clients} connected ({tr.peer}); streaming from sample {k}")
        if start_delay_s:  # e.g. a pty: give the host time to open the port (opening flushes its input)
            time.sleep(start_delay_s)
        return True

    try:
        if not next_client(0):
            return log
        t0 = time.monotonic()
        log.started_monotonic_s = t0
        base_t, base_k = t0, 0  # schedule anchor: sample k is due at base_t + (k - base_k) / rate
        next_stall = t0 + faults.stall_every_s if faults.stall_s else None
        next_disc = t0 + faults.disconnect_every_s if faults.disconnect_every_s else None
        k = 0
        while True:
            now = time.monotonic()
            if over(now, k):
                break
            if not tr.connected:  # the client went away: serve the next one, from sample k on
                say(f"client {log.clients} disconnected; waiting for the next client")
                if not next_client(k):
                    break
                base_t, base_k = time.monotonic(), k
                continue
            if next_disc is not None and now >= next_disc:
                tr.disconnect()
                log.disconnects += 1
                say(f"client {log.clients}: link dropped (fault); waiting for a client")
                time.sleep(0.05)
                if not next_client(k):
                    break
                next_disc = time.monotonic() + faults.disconnect_every_s
                base_t, base_k = time.monotonic(), k
                continue
            if next_stall is not None and now >= next_stall:
                time.sleep(faults.stall_s)
                log.stalls += 1
                next_stall = time.monotonic() + faults.stall_every_s
                base_t, base_k = time.monotonic(), k
                continue
            vals = src.values[k % T]
            if protocol == "poll":
                req = tr.read()
                if not req:
                    time.sleep(0.0005)
                    continue
                for _ in range(req.count(b"\n")):
                    log.polls += 1
                    kk = base_k + int((time.monotonic() - base_t) * rate)
                    _send(tr, encode_poll_reply(src.values[kk % T]), kk, faults, rng, log)
                    k = kk + 1
                continue
            due = base_t + (k - base_k) / rate
            if now < due:
                time.sleep(min(due - now, 0.01))
                continue
            tr.read()  # drain what the host sent (and notice a client that has gone)
            if not tr.connected:
                continue
            if protocol == "frames":
                data = encode_frame(k & 0xFFFF, int(k * 1e6 / rate), vals)
            else:
                data = encode_text(vals)
            _send(tr, data, k, faults, rng, log)
            k += 1
        tr.linger()
    finally:
        tr.close()
    return log


def check_rate(rate_hz: float | None) -> None:
    """Raise DeviceError unless ``rate_hz`` is None (the source's rate) or in (0, MAX_RATE_HZ] Hz."""
    if rate_hz is not None and not 0 < rate_hz <= MAX_RATE_HZ:
        raise DeviceError(f"--rate must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate_hz:g}")


def _send(tr: _Transport, data: bytes, k: int, faults: Faults, rng: np.random.Generator, log: ServeLog) -> None:
    out = faults.apply(data, rng)
    if tr.write(out):
        (log.sent if out == data else log.corrupted).append(k)
    else:
        log.unsent.append(k)

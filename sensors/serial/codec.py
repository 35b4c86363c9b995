"""Serial framings of tactile sensor boards: pure incremental decoders and the matching encoders.

Three framings (docs/real-sensors.md):

``text``   ``value[,value...]\\n`` lines (commas, semicolons, tabs or spaces), ``\\r`` ignored; the usual
           Arduino output. No integrity check: a line that does not parse, or whose number of values
           differs from the first good line, is counted in ``crc_errors`` ("bad lines").
``poll``   poll-and-reply binary: the host writes ``\\n``, the board answers with N little-endian
           float32. There is no framing in-band; a reply boundary is marked by the host calling
           ``poll()`` before it polls again, which discards (and counts) a short or overlong reply: one
           poll, at most one reply. A reply with a non-finite value is counted as bad. ``timeout()``
           (the host gave up waiting) counts the poll as dropped and discards everything up to the
           next ``poll()`` as late bytes (``late_bytes``): a late reply is never taken for the next
           poll's.
``frames`` piezotwin frames: COBS(``version u8 | seq u16 | t_device_us u32 | payload | crc16``) + 0x00,
           all little-endian, payload = N float32, version 1. CRC-16/CCITT-FALSE (poly 0x1021, init
           0xFFFF, no reflection, xorout 0; check value 0x29B1 for b"123456789") over the bytes
           before it.

A decoder is a pure state machine: ``feed(bytes) -> list[Frame]``; it never blocks, never raises on
bad input, and resynchronises on its own. ``stats()`` gives cumulative counters:

* ``frames``: frames decoded;
* ``crc_errors``: rejected units (a corrupted frame or a run of garbage between good frames: COBS,
  version, length or CRC check failed; a bad text line; a short or non-finite poll reply);
* ``frames_dropped``: frames missing according to the sequence numbers (``frames``), or polls that got
  no complete reply (``poll``); 0 for ``text`` (no sequence number);
* ``garbage_bytes``: bytes that were not part of a decoded frame.

Frames resynchronisation: a 0x00-delimited chunk that fails is searched for frames. An intact frame
is always a suffix of its chunk (it ends at its own delimiter), so the shortest suffix that is a valid
frame is taken first; the bytes before it are then scanned for a valid frame ending at any COBS
code-chain landing point from any start offset. So no intact frame is lost to garbage glued in front
of it or to a damaged neighbour that lost its delimiter, and a frame that lost only its delimiter is
still recovered; the sequence numbers then say how many frames were lost.
"""

from __future__ import annotations

import binascii
import math
import re
import struct
from typing import NamedTuple

__all__ = [
    "FRAME_VERSION",
    "PROTOCOLS",
    "Frame",
    "FrameDecoder",
    "PollDecoder",
    "TextDecoder",
    "cobs_decode",
    "cobs_encode",
    "crc16_ccitt_false",
    "encode_frame",
    "encode_poll_reply",
    "encode_text",
    "make_decoder",
]

PROTOCOLS = ("text", "poll", "frames")
FRAME_VERSION = 1
_HEADER = struct.Struct("<BHI")  # version, seq, t_device_us
_MIN_FRAME = _HEADER.size + 2  # header + crc, empty payload
MAX_FRAME_BYTES = 4096  # a chunk longer than this without a delimiter is dropped
MAX_LINE_BYTES = 1024


class Frame(NamedTuple):
    """One decoded sample: values, sequence number (-1 if the framing has none), device time in µs (-1)."""

    values: tuple[float, ...]
    seq: int = -1
    t_device_us: int = -1


# --------------------------------------------------------------------------- CRC-16 and COBS


def _make_crc_table() -> list[int]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) if c & 0x8000 else (c << 1)
        table.append(c & 0xFFFF)
    return table


_CRC_TABLE = _make_crc_table()


def crc16_ccitt_false(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, xorout 0): ``binascii.crc_hqx`` (C)."""
    return binascii.crc_hqx(data, crc)


def _crc16_reference(data: bytes, crc: int = 0xFFFF) -> int:
    """The same CRC, table-driven in Python (the tests check crc16_ccitt_false against it)."""
    t = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) & 0xFF00) ^ t[(crc >> 8) ^ b]
    return crc


def cobs_encode(data: bytes) -> bytes:
    """Consistent-overhead byte stuffing: the result has no 0x00 (the delimiter is not appended)."""
    out = bytearray([0])
    code_i, code = 0, 1
    for b in data:
        if b == 0:
            out[code_i] = code
            code_i, code = len(out), 1
            out.append(0)
        else:
            out.append(b)
            code += 1
            if code == 0xFF:
                out[code_i] = code
                code_i, code = len(out), 1
                out.append(0)
    out[code_i] = code
    return bytes(out)


def cobs_decode(enc: bytes) -> bytes | None:
    """Inverse of cobs_encode; None if ``enc`` is not a valid COBS encoding (zero byte, bad chain)."""
    out = bytearray()
    i, n = 0, len(enc)
    while i < n:
        code = enc[i]
        if code == 0 or i + code > n:
            return None
        block = enc[i + 1 : i + code]
        if 0 in block:
            return None
        out += block
        i += code
        if code < 0xFF and i < n:
            out.append(0)
    return bytes(out)


# --------------------------------------------------------------------------- encoders


def encode_frame(seq: int, t_device_us: int, values, version: int = FRAME_VERSION) -> bytes:
    """One piezotwin frame: COBS(header | float32 payload | crc16) + 0x00."""
    body = _HEADER.pack(version & 0xFF, seq & 0xFFFF, t_device_us & 0xFFFFFFFF)
    body += struct.pack(f"<{len(values)}f", *values)
    body += struct.pack("<H", crc16_ccitt_false(body))
    return cobs_encode(body) + b"\x00"


def encode_poll_reply(values) -> bytes:
    return struct.pack(f"<{len(values)}f", *values)


def encode_text(values, fmt: str = "{:.7g}", sep: str = ",") -> bytes:
    return (sep.join(fmt.format(v) for v in values) + "\n").encode("ascii")


# --------------------------------------------------------------------------- decoders


class _Decoder:
    protocol = ""

    def __init__(self, n_values: int | None = None):
        self.n_values = n_values
        self.frames = 0
        self.crc_errors = 0
        self.frames_dropped = 0
        self.garbage_bytes = 0
        self.bytes_in = 0

    def stats(self) -> dict[str, int]:
        return {
            "frames": self.frames,
            "crc_errors": self.crc_errors,
            "frames_dropped": self.frames_dropped,
            "garbage_bytes": self.garbage_bytes,
            "bytes": self.bytes_in,
        }

    def feed(self, data: bytes) -> list[Frame]:  # pragma: no cover - abstract
        raise NotImplementedError

    def poll(self) -> None:
        """The host is about to poll (only meaningful for ``poll``)."""

    def timeout(self) -> None:
        """The host gave up waiting for the reply to its last poll (only meaningful for ``poll``)."""


_SPLIT = re.compile(rb"[,;\s]+")


class TextDecoder(_Decoder):
    """``value[,value...]\\n`` lines; ``time_column`` (index) takes that column as device time in s."""

    protocol = "text"

    def __init__(self, n_values: int | None = None, time_column: int | None = None):
        super().__init__(n_values)
        self.time_column = time_column
        self._buf = bytearray()
        self._n_cols: int | None = None if n_values is None else n_values + (time_column is not None)

    def feed(self, data: bytes) -> list[Frame]:
        self.bytes_in += len(data)
        self._buf += data
        out: list[Frame] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > MAX_LINE_BYTES:  # no newline in sight: garbage
                    self.crc_errors += 1
                    self.garbage_bytes += len(self._buf)
                    self._buf.clear()
                return out
            line = bytes(self._buf[:i])
            del self._buf[: i + 1]
            f = self._parse(line)
            if f is not None:
                out.append(f)
                self.frames += 1
            elif line.strip():
                self.crc_errors += 1
                self.garbage_bytes += len(line) + 1

    def _parse(self, line: bytes) -> Frame | None:
        toks = [t for t in _SPLIT.split(line.strip()) if t]
        if not toks or len(line) > MAX_LINE_BYTES:
            return None
        try:
            vals = [float(t) for t in toks]
        except ValueError:
            return None
        if self._n_cols is None:
            self._n_cols = len(vals)
        elif len(vals) != self._n_cols:
            return None
        t_us = -1
        if self.time_column is not None:
            if not -len(vals) <= self.time_column < len(vals) or not math.isfinite(vals[self.time_column]):
                return None
            t_us = int(round(vals.pop(self.time_column) * 1e6))
        return Frame(tuple(vals), -1, t_us)


class PollDecoder(_Decoder):
    """Replies of ``n_values`` little-endian float32; call ``poll()`` before each poll."""

    protocol = "poll"

    def __init__(self, n_values: int = 1):
        super().__init__(n_values)
        if n_values is None or n_values < 1:
            raise ValueError("poll protocol needs n_values >= 1")
        self._size = 4 * n_values
        self._fmt = struct.Struct(f"<{n_values}f")
        self._buf = bytearray()
        self._polls = 0
        self._answered = True  # this poll got a good reply
        self._replied = False  # this poll's reply (good or bad) has been read: more bytes are overlong
        self._late = False  # the host gave up on this poll: bytes until the next poll are late
        self.late_bytes = 0

    def stats(self) -> dict[str, int]:
        return {**super().stats(), "late_bytes": self.late_bytes}

    def poll(self) -> None:
        if self._buf:  # a short or overlong reply
            self.crc_errors += 1
            self.garbage_bytes += len(self._buf)
            self._buf.clear()
        if not self._answered:
            self.frames_dropped += 1
        self._polls += 1
        self._answered = self._replied = self._late = False

    def timeout(self) -> None:
        if self._late or self._replied or not self._polls:
            return
        self.frames_dropped += 1
        self._answered = self._late = True
        self._discard_late(len(self._buf))
        self._buf.clear()

    def _discard_late(self, n: int) -> None:
        self.late_bytes += n
        self.garbage_bytes += n

    def feed(self, data: bytes) -> list[Frame]:
        self.bytes_in += len(data)
        if self._late:
            self._discard_late(len(data))
            return []
        self._buf += data
        out: list[Frame] = []
        while len(self._buf) >= self._size and not (self._replied and self._polls):
            vals = self._fmt.unpack_from(self._buf)
            del self._buf[: self._size]
            self._replied = True
            if all(math.isfinite(v) for v in vals):
                out.append(Frame(vals))
                self.frames += 1
                self._answered = True
            else:
                self.crc_errors += 1
                self.garbage_bytes += self._size
        return out


class FrameDecoder(_Decoder):
    """COBS frames with sequence number and CRC-16 (see the module docstring)."""

    protocol = "frames"

    def __init__(self, n_values: int | None = None, version: int = FRAME_VERSION):
        super().__init__(n_values)
        self.version = version
        self._buf = bytearray()
        self._last_seq: int | None = None
        self._overflow = False

    def feed(self, data: bytes) -> list[Frame]:
        self.bytes_in += len(data)
        out: list[Frame] = []
        start = 0
        while True:
            i = data.find(b"\x00", start)
            if i < 0:
                rest = data[start:]
                if self._overflow:
                    self.garbage_bytes += len(rest)
                else:
                    self._buf += rest
                    if len(self._buf) > MAX_FRAME_BYTES:
                        self.crc_errors += 1
                        self.garbage_bytes += len(self._buf)
                        self._buf.clear()
                        self._overflow = True
                return out
            if self._overflow:
                self.garbage_bytes += i - start
                self._overflow = False
            else:
                self._buf += data[start:i]
                if self._buf:
                    self._chunk(bytes(self._buf), out)
                    self._buf.clear()
            start = i + 1

    # a chunk: the bytes between two delimiters
    def _chunk(self, chunk: bytes, out: list[Frame]) -> None:
        """Decode one delimiter-to-delimiter chunk: its shortest suffix that is a valid frame, and before it
        the frames that lost their delimiter (searched left to right); the rest is counted as bad.

        An intact frame (its bytes and its delimiter) is always a suffix of its chunk, so the suffixes are
        tried first, shortest first: a longer valid suffix would contain it (a CRC collision, or a frame
        rebuilt from bytes borrowed from it), and the search before it never overlaps it. Searching left to
        right only can lose the intact frame: a truncated frame whose lost bytes happen to equal the first
        bytes of the next frame decodes with those borrowed bytes, and the next (intact) frame then has no
        start left (issue 17, item 1). The common case, a chunk that is one valid frame, is taken as is."""
        f = self._try(chunk)
        if f is not None:
            self._emit(f, out)
            return
        tail = self._valid_suffix(chunk)
        n = len(chunk) if tail is None else tail[0]
        if n:
            self._scan(chunk, n, out)
        if tail is not None:
            self._emit(tail[1], out)

    def _valid_suffix(self, chunk: bytes) -> tuple[int, Frame] | None:
        """``(start, frame)`` of the shortest suffix of ``chunk`` that is a valid frame, or None.

        Only starts whose COBS encoding decodes to the version byte first are tried (found with
        ``bytes.rfind``), and of those only the ones whose code chain lands exactly on the chunk's end."""
        n = len(chunk)
        lo = max(0, n - MAX_FRAME_BYTES)
        if self.version == 0:  # the first decoded byte is 0: the first code is 1
            needle, shift = b"\x01", 0
        else:  # the first code is >= 2 and the next byte is the version
            needle, shift = bytes([self.version]), 1
        i = chunk.rfind(needle, lo + shift, n)
        while i >= lo + shift:
            s = i - shift
            if n - s > _MIN_FRAME and (shift == 0 or chunk[s] >= 2) and self._lands_at_end(chunk, s):
                f = self._try(chunk[s:])
                if f is not None:
                    return s, f
            i = chunk.rfind(needle, lo + shift, i)
        return None

    @staticmethod
    def _lands_at_end(chunk: bytes, s: int) -> bool:
        """Whether the COBS code chain from ``s`` ends exactly at the end of ``chunk``."""
        n, p = len(chunk), s
        while p < n:
            p += chunk[p]
        return p == n

    def _scan(self, chunk: bytes, n: int, out: list[Frame]) -> None:
        """Emit the frames found in ``chunk[:n]`` left to right (each start tried in turn); count the rest."""
        s, bad_from = 0, None
        while s < n:
            end = self._scan_from(chunk, s, n)
            if end is None:
                if bad_from is None:
                    bad_from = s
                s += 1
                continue
            if bad_from is not None:
                self._bad(s - bad_from)
                bad_from = None
            self._emit(self._try(chunk[s:end]), out)
            s = end
        if bad_from is not None:
            self._bad(n - bad_from)

    def _first_byte_ok(self, chunk: bytes, s: int) -> bool:
        """Whether a COBS encoding starting at ``s`` decodes to a first byte equal to the version (cheap filter)."""
        code = chunk[s]
        first = chunk[s + 1] if code >= 2 and s + 1 < len(chunk) else 0
        return first == self.version

    def _scan_from(self, chunk: bytes, s: int, n: int) -> int | None:
        """The first COBS code-chain landing point from ``s`` (at most ``n``) that closes a valid frame."""
        if not self._first_byte_ok(chunk, s):
            return None
        p, limit = s, min(n, s + MAX_FRAME_BYTES)
        while p < limit:
            code = chunk[p]
            p += code
            if p > limit:
                return None
            if p - s > _MIN_FRAME and self._try(chunk[s:p]) is not None:
                return p
        return None

    def _try(self, enc: bytes) -> Frame | None:
        if len(enc) <= _MIN_FRAME:
            return None
        body = cobs_decode(enc)
        if body is None or len(body) < _MIN_FRAME or body[0] != self.version:
            return None
        n_pay = len(body) - _MIN_FRAME
        if n_pay % 4 or (self.n_values is not None and n_pay != 4 * self.n_values):
            return None
        if crc16_ccitt_false(body[:-2]) != int.from_bytes(body[-2:], "little"):
            return None
        _, seq, t_us = _HEADER.unpack_from(body)
        vals = struct.unpack_from(f"<{n_pay // 4}f", body, _HEADER.size)
        return Frame(vals, seq, t_us)

    def _bad(self, n_bytes: int) -> None:
        self.crc_errors += 1
        self.garbage_bytes += n_bytes

    def _emit(self, f: Frame, out: list[Frame]) -> None:
        if self._last_seq is not None:
            gap = (f.seq - self._last_seq - 1) & 0xFFFF
            if gap < 0x8000:  # larger: a restart or reordering, not a loss
                self.frames_dropped += gap
        self._last_seq = f.seq
        self.frames += 1
        out.append(f)


def make_decoder(protocol: str, n_values: int | None = None) -> _Decoder:
    if protocol == "text":
        return TextDecoder(n_values)
    if protocol == "poll":
        return PollDecoder(n_values or 1)
    if protocol == "frames":
        return FrameDecoder(n_values)
    raise ValueError(f"unknown protocol {protocol!r} (allowed: {', '.join(PROTOCOLS)})")

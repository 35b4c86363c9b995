"""Serial decoders: exact round trips, split reads at every offset, and hypothesis fuzzing (truncation, bit
flips, dropped bytes, garbage): no crash, no intact frame lost, every loss visible in the counters."""

import math
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sensors.serial.codec import (
    FrameDecoder,
    PollDecoder,
    TextDecoder,
    _crc16_reference,
    cobs_decode,
    cobs_encode,
    crc16_ccitt_false,
    encode_frame,
    encode_poll_reply,
    encode_text,
    make_decoder,
)

# examples per test, derandomization and the database come from the hypothesis profile (tests/conftest.py):
# derandomized in the default run, randomized with PIEZOTWIN_HYPOTHESIS_PROFILE=fuzz and in the slow tests
FUZZ = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
# the slow, randomized run of the fuzz tests: many more examples, a new random draw each run
FUZZ_LONG = settings(FUZZ, max_examples=4000, derandomize=False, database=None, print_blob=True)
f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


def test_crc16_ccitt_false_check_value():
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF


@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_crc16_equals_the_table_driven_reference(data, init):
    assert crc16_ccitt_false(data, init) == _crc16_reference(data, init)


@pytest.mark.parametrize("n", [0, 1, 253, 254, 255, 508, 509, 700])
def test_cobs_edges(n):
    for data in (bytes(n), bytes([7]) * n, bytes(range(256)) * (n // 256) + bytes(range(n % 256))):
        enc = cobs_encode(data)
        assert 0 not in enc and cobs_decode(enc) == data


@given(st.binary(max_size=600))
@FUZZ
def test_cobs_roundtrip(data):
    enc = cobs_encode(data)
    assert 0 not in enc
    assert cobs_decode(enc) == data


@given(st.binary(max_size=100))
def test_cobs_decode_never_crashes(data):
    cobs_decode(data)


def _frames(n, width=2, start=0):
    vals = [tuple(float(struct.unpack("<f", struct.pack("<f", (k * 0.37 + j) % 97))[0]) for j in range(width))
            for k in range(start, start + n)]
    return [encode_frame(k, k * 1000, v) for k, v in zip(range(start, start + n), vals)], vals


def test_frames_roundtrip_and_split_at_every_offset():
    enc, vals = _frames(6)
    stream = b"".join(enc)
    for cut in range(len(stream) + 1):
        d = FrameDecoder()
        out = d.feed(stream[:cut]) + d.feed(stream[cut:])
        assert [f.values for f in out] == vals
        assert [f.seq for f in out] == list(range(6)) and out[3].t_device_us == 3000
        assert d.crc_errors == 0 and d.frames_dropped == 0
    d = FrameDecoder()  # byte by byte
    assert [f.values for b in stream for f in d.feed(bytes([b]))] == vals


def test_frames_resync_after_garbage_and_lost_delimiter():
    enc, vals = _frames(4)
    d = FrameDecoder()
    # garbage glued in front of frame 0, frame 1's delimiter lost, frame 2 truncated, frame 3 intact
    stream = b"\x13\x37garbage" + enc[0] + enc[1][:-1] + enc[2][:5] + enc[3]
    out = d.feed(stream)
    assert [f.seq for f in out] == [0, 1, 3]
    assert d.frames_dropped == 1 and d.crc_errors >= 2


def test_frames_truncated_frames_then_intact_frame_issue_17():
    # frames 13, 14, 15 truncated by 2 bytes (last COBS byte and delimiter lost), 16 intact: 15's lost byte
    # equals 16's first byte, so 15 decoded by borrowing it and 16 was lost
    enc = [encode_frame(k, k * 1000, [k * 0.37]) for k in range(12, 18)]
    stream = enc[0] + enc[1][:-2] + enc[2][:-2] + enc[3][:-2] + enc[4] + enc[5]
    d = FrameDecoder()
    out = d.feed(stream)
    assert [f.seq for f in out] == [12, 16, 17]
    assert out[1].values == struct.unpack("<f", struct.pack("<f", 16 * 0.37))
    assert d.frames_dropped == 3 and d.crc_errors == 1


@pytest.mark.parametrize("width", [1, 2, 3])
def test_frames_intact_frame_survives_any_truncated_neighbours(width):
    """Systematic: three frames that lost their last 1-3 bytes (delimiter included), then an intact frame,
    for 400 sequence numbers: the intact frame always decodes, with its values."""
    for base in range(400):
        for lost in (1, 2, 3):
            enc, vals = _frames(5, width, start=base)
            stream = enc[0] + b"".join(e[:-lost] for e in enc[1:4]) + enc[4]
            d = FrameDecoder()
            got = {f.seq: f.values for f in d.feed(stream)}
            assert got.get(base + 4) == vals[4], (base, lost, sorted(got))
            assert got.get(base) == vals[0]
            assert all(v == vals[seq - base] for seq, v in got.items())


def test_sequence_wraps_without_a_false_gap():
    d = FrameDecoder()
    out = d.feed(encode_frame(65534, 0, [1.0]) + encode_frame(65535, 0, [1.0]) + encode_frame(0, 0, [1.0])
                 + encode_frame(2, 0, [1.0]))
    assert [f.seq for f in out] == [65534, 65535, 0, 2] and d.frames_dropped == 1


def test_overlong_chunk_is_dropped_and_counted():
    d = FrameDecoder()
    enc, _ = _frames(1)
    assert d.feed(b"\x01" * 10000) == []
    assert [f.seq for f in d.feed(b"\x00" + enc[0])] == [0]
    assert d.crc_errors == 1


@st.composite
def corrupted_streams(draw):
    """Frames, each either intact or damaged (bit flips, dropped bytes, truncation), with garbage between."""
    n = draw(st.integers(1, 12))
    width = draw(st.integers(1, 4))
    enc, vals = _frames(n, width, start=draw(st.integers(0, 65535 - 12)))
    parts, intact = [], []
    for k, e in enumerate(enc):
        if draw(st.booleans()):
            garbage = draw(st.binary(max_size=12))
            parts.append(garbage)
        kind = draw(st.sampled_from(["ok", "ok", "flip", "drop", "trunc", "tail"]))
        if kind == "ok":
            parts.append(e)
            intact.append(k)
            continue
        b = bytearray(e)
        if kind == "flip":
            for _ in range(draw(st.integers(1, 3))):
                i = draw(st.integers(0, len(b) - 1))
                b[i] ^= 1 << draw(st.integers(0, 7))
        elif kind == "drop":
            del b[draw(st.integers(0, len(b) - 1))]
        elif kind == "tail":  # the last bytes lost, delimiter included: glued to the next frame
            b = b[: len(b) - draw(st.integers(1, 3))]
        else:
            b = b[: draw(st.integers(0, len(b) - 1))]
        if bytes(b) == e:
            intact.append(k)
        parts.append(bytes(b))
    return parts, enc, vals, intact


@given(corrupted_streams(), st.data())
@FUZZ
def test_fuzz_frames_no_intact_frame_lost(case, data):
    _check_no_intact_frame_lost(case, data)


@pytest.mark.slow
@given(corrupted_streams(), st.data())
@FUZZ_LONG
def test_fuzz_frames_no_intact_frame_lost_long(case, data):
    """The same property, randomized (a new draw each run) and with many more examples."""
    _check_no_intact_frame_lost(case, data)


def _check_no_intact_frame_lost(case, data):
    parts, enc, vals, intact = case
    seq0 = struct.unpack_from("<H", cobs_decode(enc[0][:-1]), 1)[0]
    sentinel = encode_frame(seq0 + len(enc), 0, [0.0] * len(vals[0]))  # an intact frame after the damage
    stream = b"".join(parts) + sentinel
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=5)))
    d = FrameDecoder()
    out, prev = [], 0
    for c in cuts + [len(stream)]:
        out += d.feed(stream[prev:c])
        prev = c
    got = {f.seq: f.values for f in out}
    assert len(got) == len(out) == d.frames
    # every intact frame arrives, even right after garbage or a damaged frame with no delimiter between
    for k in intact:
        assert got.get(seq0 + k) == vals[k], (k, intact, sorted(got))
    assert (seq0 + len(enc)) in got
    # nothing false: every decoded frame is one that was sent, with its values
    for seq, v in got.items():
        assert seq == seq0 + len(enc) or v == vals[seq - seq0]
    # and every lost frame is counted: sequence gaps between the first decoded frame and the sentinel
    first = min(got) - seq0
    assert d.frames_dropped == (len(enc) - first) - (len(got) - 1)


@given(st.binary(max_size=400), st.integers(1, 50))
@FUZZ
def test_fuzz_garbage_never_crashes(garbage, step):
    for dec in (FrameDecoder(), TextDecoder(), PollDecoder(3)):
        for i in range(0, len(garbage), step):
            dec.poll()
            for f in dec.feed(garbage[i : i + step]):
                assert all(isinstance(v, float) for v in f.values)
        s = dec.stats()
        assert s["bytes"] == len(garbage)


def test_text_lines_split_at_every_offset_and_bad_lines_counted():
    rows = [(1.5, -2.0), (3.0, 4.25), (1e-3, 7.0)]
    stream = b"".join(encode_text(r) for r in rows[:2]) + b"oops,xx\r\n" + b"1,2,3\n" + encode_text(rows[2])
    for cut in range(len(stream) + 1):
        d = TextDecoder()
        out = d.feed(stream[:cut]) + d.feed(stream[cut:])
        assert [f.values for f in out] == rows
        assert d.crc_errors == 2  # a non-number line and a line with the wrong number of values


def test_text_separators_and_time_column():
    d = TextDecoder(time_column=0)
    out = d.feed(b"0.5 10;20\n\n1.0\t11,21\r\n")
    assert [f.values for f in out] == [(10.0, 20.0), (11.0, 21.0)] and [f.t_device_us for f in out] == [500000, 1000000]


@given(st.lists(st.lists(f32, min_size=2, max_size=2), max_size=20), st.integers(1, 30))
@FUZZ
def test_fuzz_text_roundtrip(rows, step):
    stream = b"".join(encode_text(r, fmt="{!r}") for r in rows)
    d = TextDecoder()
    out = [f for i in range(0, len(stream), step) for f in d.feed(stream[i : i + step])]
    assert [f.values for f in out] == [tuple(r) for r in rows] and d.crc_errors == 0


def test_poll_replies_short_and_nonfinite_counted():
    d = PollDecoder(2)
    d.poll()
    assert [f.values for f in d.feed(encode_poll_reply([1.0, 2.0]))] == [(1.0, 2.0)]
    d.poll()
    assert d.feed(encode_poll_reply([3.0, 4.0])[:5]) == []  # short reply (a byte lost)
    d.poll()  # next poll: the partial reply is dropped and counted
    assert d.crc_errors == 1 and d.frames_dropped == 1
    assert d.feed(encode_poll_reply([math.nan, 1.0])) == [] and d.crc_errors == 2
    d.poll()
    d.poll()  # no reply at all
    assert d.frames_dropped == 3


@given(st.lists(st.lists(f32, min_size=3, max_size=3), max_size=20), st.integers(1, 13))
@FUZZ
def test_fuzz_poll_split_reads(rows, step):
    d = PollDecoder(3)
    out = []
    for r in rows:
        d.poll()
        b = encode_poll_reply(r)
        for i in range(0, len(b), step):
            out += d.feed(b[i : i + step])
    assert [f.values for f in out] == [tuple(r) for r in rows] and d.crc_errors == 0


def test_unknown_protocol():
    with pytest.raises(ValueError, match="unknown protocol 'xml'"):
        make_decoder("xml")


def test_poll_late_reply_discarded_and_one_reply_per_poll():
    d = PollDecoder(2)
    d.poll()
    assert d.feed(encode_poll_reply([1.0, 2.0])[:3]) == []
    d.timeout()  # the host gave up waiting: the rest of this reply is late, never a reply
    assert d.feed(encode_poll_reply([1.0, 2.0])[3:]) == [] and d.frames_dropped == 1
    d.poll()
    assert [f.values for f in d.feed(encode_poll_reply([3.0, 4.0]) * 2)] == [(3.0, 4.0)]  # overlong: one reply
    d.poll()
    s = d.stats()
    assert (s["late_bytes"], s["crc_errors"], s["frames_dropped"], s["frames"]) == (8, 1, 1, 1)

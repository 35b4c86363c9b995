"""serve <-> capture over loopback sockets and ptys: every intact frame arrives, every corrupted one is
counted, streams are aligned on host time, restarts append, a crash or a vanished port keeps the data."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from sensors.data.recording import Recording
from sensors.serial.board import DeviceError, Faults, Source, serve
from sensors.serial.capture import (
    RAW,
    CaptureError,
    StreamSpec,
    build_recording,
    capture,
    rawlog_path,
    read_records,
)

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def ramp_source(n=2000, rate=500.0, width=1):
    k = np.arange(n, dtype=np.float32)
    vals = np.stack([k / rate + j for j in range(width)], 1).astype(np.float32)  # value = device time (+ j)
    return Source(vals, rate, "s", "ramp", "test")


class Served:
    """serve() in a thread; .url once listening, .log when done."""

    def __init__(self, src, url, protocol, **kw):
        self.ready = threading.Event()
        self.stop = threading.Event()
        self.url = self.log = self.exc = None

        def run():
            try:
                kw.setdefault("start_delay_s", 0.2)  # opening a port flushes its input, as on a real line
                self.log = serve(src, url, protocol, on_ready=self._on_ready, should_stop=self.stop.is_set,
                                 client_timeout_s=5.0, **kw)
            except BaseException as e:  # noqa: BLE001
                self.exc = e
                self.ready.set()

        self.t = threading.Thread(target=run, daemon=True)
        self.t.start()
        assert self.ready.wait(5.0)
        if self.exc:
            raise self.exc

    def _on_ready(self, url):
        self.url = url
        self.ready.set()

    def join(self):
        self.stop.set()
        self.t.join(5.0)
        assert not self.t.is_alive()
        return self.log


def test_frames_with_faults_every_intact_frame_arrives_every_loss_counted(tmp_path):
    src = ramp_source(300)
    sv = Served(src, "socket://127.0.0.1:0", "frames", max_frames=300,
                faults=Faults(bit_flips=0.01, drop_bytes=0.005, seed=3))
    res = capture([StreamSpec(sv.url, "frames", "board", units="s")], tmp_path / "cap.h5", duration_s=10)
    log = sv.join()
    assert res.reason.startswith("port vanished")  # the board stopped after 300 frames
    assert log.corrupted and len(log.sent) + len(log.corrupted) == 300
    with Recording(tmp_path / "cap.h5") as rec:
        ep = rec.episode_ids[0]
        seq, vals = rec.read(ep, "seq"), rec.read(ep, "board")[:, 0]
        a = rec.episode_attrs(ep)
        assert rec.attrs["source"] == "real" and rec.units(ep, "board") == "s" and a["protocol"] == "frames"
    got = set(seq.tolist())
    assert set(log.sent) <= got  # every intact frame arrived
    np.testing.assert_array_equal(vals, src.values[seq, 0])  # and nothing false
    missing = set(range(min(got), max(got) + 1)) - got
    assert missing <= set(log.corrupted)
    assert a["frames_dropped"] == len(missing) and a["crc_errors"] >= 1
    assert a["crc_errors"] >= len(missing) // 2  # a bad chunk can swallow two frames at most


def test_text_over_pty(tmp_path):
    src = ramp_source(200, rate=400.0, width=2)
    link = tmp_path / "ttyV0"
    sv = Served(src, f"pty:{link}", "text", max_frames=200, start_delay_s=0.5)
    assert link.is_symlink()
    res = capture([StreamSpec(str(link), "text", "pad", n_values=2)], tmp_path / "t.h5", duration_s=1.5)
    log = sv.join()
    assert len(log.sent) == 200 and res.reason.startswith("port vanished")  # the board closed the pty
    with Recording(tmp_path / "t.h5") as rec:
        ep = rec.episode_ids[0]
        v = rec.read(ep, "pad")
        assert rec.episode_attrs(ep)["crc_errors"] == 0
    # opening a pty flushes what is already in it: on a busy machine the first lines may go there
    assert len(v) >= 180
    np.testing.assert_allclose(v, src.values[-len(v):], rtol=1e-6)


def _poll_capture(tmp_path, faults=None):
    """A board served with ``poll``, captured for 0.5 s; checks what holds however loaded the machine is."""
    src = ramp_source(5000, rate=1000.0, width=3)
    sv = Served(src, "socket://127.0.0.1:0", "poll", duration_s=5, faults=faults)
    res = capture([StreamSpec(sv.url, "poll", "velostat", n_values=3)], tmp_path / "p.h5", duration_s=0.5)
    log = sv.join()
    assert res.reason == "duration"
    with Recording(tmp_path / "p.h5") as rec:
        ep = rec.episode_ids[0]
        v = rec.read(ep, "velostat")
        h = rec.read(ep, "host_time_ns")
        a = rec.episode_attrs(ep)
        reads = rec.read(ep, "velostat_raw_reads")
    polls, timeouts = (reads[:, 2] == 3).sum(), (reads[:, 2] == 5).sum()
    # the board got every poll and answered each (a reply written after the capture closed is unsent)
    assert polls == log.polls == len(log.sent) + len(log.unsent) and not log.corrupted
    # which poll each recorded reply answers, by the order of the raw log: the reply to the board's j-th
    # poll is sample log.sent[j], so a late reply taken for the next poll's shows up here
    poll_of_read = np.cumsum(reads[:, 2] == 3) - 1
    row = {int(t): k for k, t in enumerate(reads[:, 0]) if reads[k, 2] == 2}
    j = np.array([poll_of_read[row[int(t)]] for t in h], np.int64)
    assert np.all(np.diff(j) > 0)  # one reply per poll
    np.testing.assert_array_equal(v, src.values[np.asarray(log.sent)[j] % len(src.values)])
    # a poll either got its reply in time or is counted dropped (the last one may be cut off by the stop)
    assert a["crc_errors"] == 0 and a["frames_dropped"] == timeouts
    assert polls - 1 <= len(v) + a["frames_dropped"] <= polls
    return v, a, timeouts


def test_poll_over_socket(tmp_path):
    v, a, _ = _poll_capture(tmp_path)
    assert len(v) > 20


def test_poll_late_reply_is_not_taken_for_the_next_polls(tmp_path):
    # the board goes quiet for 0.3 s (> reply_timeout_s) every 0.15 s: polls are answered late
    v, a, timeouts = _poll_capture(tmp_path, Faults(stall_s=0.3, stall_every_s=0.15))
    assert timeouts >= 1 and a["velostat_late_bytes"] >= 12 and len(v) > 5


def test_two_streams_aligned_on_host_time(tmp_path):
    board = Served(ramp_source(4000, rate=400.0), "socket://127.0.0.1:0", "frames", duration_s=3)
    cell = Served(ramp_source(4000, rate=250.0), "socket://127.0.0.1:0", "text", duration_s=3)
    res = capture([StreamSpec(board.url, "frames", "board"), StreamSpec(cell.url, "text", "cell")],
                  tmp_path / "two.h5", duration_s=1.0)
    blog, clog = board.join(), cell.join()
    assert res.reason == "duration"
    with Recording(tmp_path / "two.h5") as rec:
        ep = rec.episode_ids[0]
        b, c = rec.read(ep, "board")[:, 0], rec.read(ep, "cell")[:, 0]
        nat = rec.read(ep, "cell_native")
        t = rec.read(ep, "time")
        assert rec.dim_names(ep, "cell_native") == ("cell_sample", "channel")
    assert 150 < len(nat) < 350 and 250 < len(b) < 550  # 250 Hz and 400 Hz for about a second
    ok = np.isfinite(c)
    assert ok.mean() > 0.9 and np.all(np.diff(t) >= 0)
    # both ramps are device time since their board started streaming; the boards start when capture's
    # client reaches each (one after the other, tens of ms apart on a loaded machine): aligned on host time
    # the two ramps differ by exactly that start offset
    offset_s = clog.started_monotonic_s - blog.started_monotonic_s
    assert np.median(np.abs(b[ok] - c[ok] - offset_s)) < 0.01


def test_restart_appends_and_torn_tail_is_dropped(tmp_path):
    out = tmp_path / "r.h5"
    for i in range(2):
        sv = Served(ramp_source(100, rate=500.0), "socket://127.0.0.1:0", "frames", max_frames=100)
        capture([StreamSpec(sv.url, "frames", "b")], out, duration_s=5)
        sv.join()
        if i == 0:  # a crash mid-record: a torn record at the end of the log
            with open(rawlog_path(out), "ab") as f:
                f.write(bytes([RAW, 0, 0, 0, 200, 0, 0, 0]) + b"torn")
    recs = list(read_records(rawlog_path(out)))
    assert recs[-1][0] != RAW or len(recs[-1][3]) != 200
    with Recording(out) as rec:
        assert rec.episode_ids == ["session-0", "session-1"] and rec.attrs["n_sessions"] == 2
        for ep in rec.episode_ids:
            assert len(rec.read(ep, "seq")) == 100
            raw = rec.read(ep, "b_raw")
            assert raw.dtype == np.uint8 and len(raw) > 100 * 9


def test_disconnect_and_reconnect(tmp_path):
    src = ramp_source(1000, rate=500.0)
    # a link cycle takes 0.6 s: 0.25 s streaming, then pyserial's close of a socket sleeps 0.3 s before the
    # capture reconnects; the board accepts no client once its duration is over. 2.0 s hold about three cycles,
    # the test asks for two: a full cycle of slack for a loaded machine
    sv = Served(src, "socket://127.0.0.1:0", "frames", duration_s=2.0, faults=Faults(disconnect_every_s=0.25),
                start_delay_s=0.05)
    res = capture([StreamSpec(sv.url, "frames", "b")], tmp_path / "d.h5", duration_s=2.6, reconnect_s=1.0)
    log = sv.join()
    assert log.disconnects >= 2
    with Recording(tmp_path / "d.h5") as rec:
        ep = rec.episode_ids[0]
        seq = rec.read(ep, "seq")
        events = [e["event"] for e in rec.episode_attrs(ep)["events"]]
        assert rec.episode_attrs(ep)["frames_dropped"] == 0
    assert events.count("reconnected") >= 2 and "disconnected" in events
    assert set(seq.tolist()) == set(log.sent)  # nothing lost across the reconnects
    assert res.reason == "duration" or res.reason.startswith("port vanished")


def test_cli_capture_port_vanishes_and_bad_input(tmp_path):
    sv = Served(ramp_source(50), "socket://127.0.0.1:0", "frames", max_frames=50)
    out = tmp_path / "v.h5"
    res = runner.invoke(app, ["capture", "--port", sv.url, "--protocol", "frames", "-o", str(out), "--duration", "10"])
    sv.join()
    assert res.exit_code == 1 and "vanished" in res.output and "valid up to the last flush" in res.output
    with Recording(out) as rec:
        assert len(rec.read(rec.episode_ids[0], "seq")) == 50
    for args, needle in [
        (["capture", "--port", "loop://", "--protocol", "xml"], "unknown protocol 'xml'"),
        (["capture", "--port", "loop://", "--protocol2", "csv"], "unknown protocol 'csv'"),
        (["capture", "--port", "nosuch://x"], "cannot open port 'nosuch://x'"),
        (["capture", "--port", str(tmp_path / "no-tty")], "cannot open port"),
        (["serve", "cnt_pdms", "--url", "pty", "--protocol", "morse"], "unknown protocol 'morse'"),
        (["serve", "cnt_pdm", "--url", "pty"], "unknown preset"),
        (["serve", "cnt_pdms", "--url", "pty", "--bit-flips", "2"], "probability"),
        # 0 is not "unset": out of range, one line naming the option and the allowed range
        (["serve", "cnt_pdms", "--url", "pty", "--rate", "0"], "--rate must be in (0, 100000] Hz, got 0"),
        (["serve", "cnt_pdms", "--url", "pty", "--rate", "-5"], "--rate must be in (0, 100000] Hz, got -5"),
        (["serve", "cnt_pdms", "--url", "pty", "--rate", "1e9"], "--rate must be in (0, 100000] Hz"),
        (["serve", "cnt_pdms", "--url", "pty", "--rate", "nan"], "--rate must be in (0, 100000] Hz, got nan"),
        (["serve", "cnt_pdms", "--url", "pty", "--frames", "0"], "--frames must be >= 1"),
        (["serve", "cnt_pdms", "--url", "pty", "--duration", "0"], "--duration must be > 0 s"),
        (["serve", "cnt_pdms", "--url", "pty", "--client-timeout", "0"], "--client-timeout must be > 0 s"),
    ]:
        res = runner.invoke(app, args + (["-o", str(tmp_path / "x.h5")] if args[0] == "capture" else []))
        assert res.exit_code == 2, (args, res.output)
        assert needle in res.output.replace("\n", " ") and res.output.count("error:") == 1
    assert not (tmp_path / "x.h5").exists()


def test_crash_loses_at_most_the_last_flush_and_rebuild(tmp_path):
    sv = Served(ramp_source(5000, rate=500.0), "socket://127.0.0.1:0", "frames", duration_s=20)
    out = tmp_path / "k.h5"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "piezotwin.cli", "capture", "--port", sv.url, "--protocol", "frames",
                          "-o", str(out), "--flush-s", "0.2"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:  # wait until data has been flushed
            if rawlog_path(out).exists() and rawlog_path(out).stat().st_size > 5000:
                break
            time.sleep(0.05)
        time.sleep(0.5)
        t_kill = time.monotonic_ns()
        p.send_signal(signal.SIGKILL)
        p.wait(5)
    finally:
        if p.poll() is None:
            p.kill()
    sv.join()
    assert not out.exists()  # killed: nothing at the final name yet
    res = runner.invoke(app, ["capture", "--rebuild", "-o", str(out)])
    assert res.exit_code == 0, res.output
    with Recording(out) as rec:
        ep = rec.episode_ids[0]
        h = rec.read(ep, "host_time_ns")
        assert len(h) > 100 and np.all(np.diff(rec.read(ep, "seq")) == 1)
    assert (t_kill - h[-1]) / 1e9 < 1.0  # at most the last second lost


def test_cli_serve_preset_over_pty(tmp_path):
    link = tmp_path / "ttyV1"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    flog = tmp_path / "faults.json"
    p = subprocess.Popen([sys.executable, "-m", "piezotwin.cli", "serve", "cnt_pdms", "--url", f"pty:{link}",
                          "--protocol", "frames", "--rate", "500", "--frames", "300", "--start-delay", "1.0",
                          "--fault-log", str(flog), "--set", "pad.taxels_x=5", "--set", "pad.taxels_y=5"],
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = p.stdout.readline()
        assert "serving resistance_measured (ohm" in line, line + p.stdout.read()
        res = capture([StreamSpec(str(link), "frames", "r", units="ohm")], tmp_path / "s.h5", duration_s=20)
        assert res.reason.startswith("port vanished")  # the board closed the pty after 300 frames
        assert p.wait(10) == 0
    finally:
        if p.poll() is None:
            p.kill()
    sent = json.loads(flog.read_text())["sent"]
    assert len(sent) == 300 and res.stats[0]["crc_errors"] == 0
    with Recording(tmp_path / "s.h5") as rec:
        ep = rec.episode_ids[0]
        r = rec.read(ep, "r")
        seq = rec.read(ep, "seq")
        assert rec.units(ep, "r") == "ohm" and np.all(r > 0)
    # opening a pty flushes what is already in it: on a very busy machine the first frames may go there
    assert seq[-1] == 299 and np.all(np.diff(seq) == 1) and len(seq) >= 290


def test_capture_errors():
    with pytest.raises(CaptureError, match="unknown protocol"):
        StreamSpec("loop://", "json")
    with pytest.raises(CaptureError, match="no raw log"):
        build_recording("/nonexistent/x.rawlog", "/nonexistent/x.h5")


def test_serve_rate_zero_is_an_error_not_the_default():
    with pytest.raises(DeviceError, match=r"--rate must be in \(0, 100000\] Hz, got 0"):
        serve(ramp_source(10), "socket://127.0.0.1:0", "frames", rate_hz=0.0)


def test_serve_takes_the_next_client_after_a_capture_disconnects(tmp_path):
    """The crash-recovery flow: capture, stop, capture again into the same file: the second capture gets the
    stream (from the next sample on), and the board says in its log who came and went (issue 17, item 2)."""
    events = []
    src = ramp_source(5000, rate=500.0)
    sv = Served(src, "socket://127.0.0.1:0", "frames", start_delay_s=0.0, on_event=events.append)
    out = tmp_path / "again.h5"
    for _ in range(2):
        res = capture([StreamSpec(sv.url, "frames", "b")], out, duration_s=0.5)
        assert res.reason == "duration" and res.stats[0].get("frames", 0) > 20, res.stats
    log = sv.join()
    assert log.clients == 2
    assert any("client 1 disconnected; waiting for the next client" in e for e in events), events
    assert any(e.startswith("client 2 connected") for e in events), events
    with Recording(out) as rec:
        seqs = [rec.read(ep, "seq") for ep in rec.episode_ids]
        dropped = [rec.episode_attrs(ep)["frames_dropped"] for ep in rec.episode_ids]
    assert len(seqs) == 2 and dropped == [0, 0]
    assert seqs[1][0] > seqs[0][-1]  # the board paused while no one was connected, and went on from there
    assert set(np.concatenate(seqs).tolist()) <= set(log.sent)


def _capture_served(tmp_path, name, n=60):
    """A board that streams n frames at 1 kHz as soon as a client connects (no start delay), captured."""
    sv = Served(ramp_source(n, rate=1000.0), "socket://127.0.0.1:0", "frames", max_frames=n, start_delay_s=0.0)
    res = capture([StreamSpec(sv.url, "frames", "b")], tmp_path / name, duration_s=10)
    log = sv.join()
    with Recording(tmp_path / name) as rec:
        ep = rec.episode_ids[0]
        return res, log, rec.read(ep, "seq"), rec.episode_attrs(ep)


def test_first_frame_is_not_lost_while_the_capture_opens(tmp_path, monkeypatch):
    """pyserial clears a socket's input at the end of open(): frame 0, sent when the board accepts, was thrown
    away when it arrived before that (issue 17, item 4). A slow open (as on a busy machine) makes it certain."""
    from serial.urlhandler import protocol_socket

    reconfigure = protocol_socket.Serial._reconfigure_port

    def slow_reconfigure(self, *a, **kw):
        time.sleep(0.2)  # the board's first frames arrive meanwhile
        return reconfigure(self, *a, **kw)

    monkeypatch.setattr(protocol_socket.Serial, "_reconfigure_port", slow_reconfigure)
    res, log, seq, a = _capture_served(tmp_path, "slow.h5")
    assert res.reason.startswith("port vanished")  # the board hung up after its frames
    assert seq.tolist() == list(range(60)) == log.sent and a["frames_dropped"] == 0


def test_first_frame_arrives_in_every_run(tmp_path):
    for run in range(5):
        res, log, seq, a = _capture_served(tmp_path, f"run{run}.h5", n=30)
        assert seq.tolist() == list(range(30)) == log.sent, (run, seq[:3])


def test_capture_reads_in_blocks_over_loopback(tmp_path):
    """Over socket:// a read took one byte (in_waiting is 1 there): 41 KB/s and a raw log 21x the data (issue
    17, item 5). 2 MB of frames must come in at >= 1 MB/s end to end (read, logged, decoded live) even on a busy
    2-core machine (it does 5 MB/s there, and 40-100 MB/s reading alone; bench/bench_serial.py)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_serial", ROOT / "bench" / "bench_serial.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    data, n_frames = bench.board_bytes(2_000_000, width=64)
    r = bench.loopback_capture(data, tmp_path, timeout_s=8.0)
    assert r["bytes"] == len(data) and r["frames"] == n_frames and r["crc_errors"] == 0, r
    assert r["bytes_per_s"] >= 1e6, r
    assert r["bytes_per_read"] >= 1000 and r["rawlog_over_data"] < 1.01, r


def test_a_capture_of_a_board_and_a_load_cell_fits_the_chain(tmp_path):
    """The real-data path from the wire: a board streaming 3 values per sample (R, x, y) at 200 Hz and a load cell
    (N) at 250 Hz, captured on host time, read as `--input board[0] --target cell` and fitted: the chain's exponent
    comes back."""
    from sensors import chain_fit as CF

    def force_at(t):  # 1.5 s presses to 2-8 N, 0.3 s ramps, 1 s apart
        k, u = np.floor(t / 2.5), np.mod(t, 2.5)
        pk = 2.0 + 6.0 * np.mod(k * 0.618, 1.0)
        return pk * np.clip(np.minimum(u / 0.3, (1.5 - u) / 0.3), 0.0, 1.0)

    p = CF.ChainParams(exponent=1.2, r0_ohm=5000.0, creep_amplitude=1e-6, r_ref_ohm=1e4, full_scale=1000.0)
    tb, tc = np.arange(0, 12, 1 / 200), np.arange(0, 12, 1 / 250)
    r = CF.total_resistance(CF.film_resistance(force_at(tb), 1 / 200, p), p)
    board = np.stack([np.minimum(r, 1e6), np.zeros_like(r), np.zeros_like(r)], 1).astype(np.float32)
    b = Served(Source(board, 200.0, "ohm", "board", "test"), "socket://127.0.0.1:0", "frames", duration_s=8)
    c = Served(Source(force_at(tc)[:, None].astype(np.float32), 250.0, "N", "cell", "test"), "socket://127.0.0.1:0",
               "text", duration_s=8)
    capture([StreamSpec(b.url, "frames", "board", units="ohm"), StreamSpec(c.url, "text", "cell", units="N")],
            tmp_path / "cap.h5", duration_s=6.0)
    b.join(), c.join()
    runs = CF.load_real_runs(tmp_path / "cap.h5", input_channel="board[0]", target="cell", rate_hz=20.0)
    assert len(runs) == 1 and runs[0].force.max() > 5.0
    fit = CF.fit_chain(runs * 2, CF.ChainParams(r_ref_ohm=1e4, full_scale=1.0, divider="high"), n_boot=0)
    assert abs(fit.params.exponent - 1.2) < 0.25, fit.params.exponent


def test_a_stream_that_stalls_is_left_empty_and_noted(tmp_path):
    """A second stream that stops sending for 1.5 s (a stall fault) is left empty on the first stream's clock over
    that stretch, not bridged by a line, and the stretch is recorded (`<name>_gaps_s`)."""
    board = Served(ramp_source(4000, rate=400.0), "socket://127.0.0.1:0", "frames", duration_s=4)
    cell = Served(ramp_source(4000, rate=250.0), "socket://127.0.0.1:0", "text", duration_s=4,
                  faults=Faults(stall_s=1.5, stall_every_s=0.8))
    capture([StreamSpec(board.url, "frames", "board"), StreamSpec(cell.url, "text", "cell")], tmp_path / "s.h5",
            duration_s=2.6)
    board.join(), cell.join()
    with Recording(tmp_path / "s.h5") as rec:
        ep = rec.episode_ids[0]
        gaps = np.asarray(rec.episode_attrs(ep)["cell_gaps_s"])
        c, t = rec.read(ep, "cell")[:, 0], rec.read(ep, "time")
    assert len(gaps) >= 1 and 1.2 < gaps[:, 1].max() < 2.5
    g0, gl = gaps[np.argmax(gaps[:, 1])]
    inside = (t > g0 + 0.05) & (t < g0 + gl - 0.05)
    assert inside.sum() > 100 and np.isnan(c[inside]).all()

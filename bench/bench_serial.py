"""Capture throughput over a loopback socket: how fast ``capture`` takes in a board's bytes.

    PYTHONPATH=. python bench/bench_serial.py [--mbytes 8] [--width 64] [--runs 3]

A thread listens on 127.0.0.1, and when the capture connects it writes ``--mbytes`` MB of piezotwin frames
(``--width`` float32 each) as fast as the socket takes them, then closes. The capture (``socket://``, framing
``frames``) reads, logs and decodes them live; ``bytes_per_s`` is the bytes received over the time from the
capture's start to its stop (the link closed and everything read was logged and decoded: the host times of
the SESSION and the stop EVENT records of the raw log), ``read_bytes_per_s`` the same up to its last read.
Also: reads per MB, raw-log size over data size, frames decoded. Writes bench/results/serial-throughput-cpu.json
(the median run, and every run). ``loopback_capture`` is also what tests/test_capture.py measures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import tempfile
import threading
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "serial-throughput-cpu.json"


def board_bytes(n_bytes: int, width: int = 64) -> tuple[bytes, int]:
    """About ``n_bytes`` of consecutive frames of ``width`` values; (bytes, number of frames)."""
    from sensors.serial.codec import encode_frame

    one = len(encode_frame(0, 0, [0.5] * width))
    n = max(1, n_bytes // one)
    data = b"".join(encode_frame(k & 0xFFFF, k * 1000, [k * 1e-3 + j for j in range(width)]) for k in range(n))
    return data, n


def loopback_capture(data: bytes, out_dir: str | os.PathLike, timeout_s: float = 30.0) -> dict:
    """Serve ``data`` once over a loopback socket to a ``capture``; what it measured (see the module docstring)."""
    from sensors.serial.capture import (
        EVENT,
        RAW,
        SESSION,
        StreamSpec,
        capture,
        rawlog_path,
        read_records,
    )

    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]

    def serve_once() -> None:
        srv.settimeout(timeout_s)
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        finally:
            srv.close()  # one client: the capture's reconnect is refused, so it stops when the data ends
        try:
            conn.sendall(data)
            conn.shutdown(socket.SHUT_WR)
            conn.settimeout(timeout_s)
            while conn.recv(4096):  # until the capture closes: a board that hangs up after its data
                pass
        except OSError:
            pass
        finally:
            conn.close()

    t = threading.Thread(target=serve_once, daemon=True)
    t.start()
    out = Path(out_dir) / "throughput.h5"
    try:
        res = capture([StreamSpec(f"socket://127.0.0.1:{port}", "frames", "board")], out, duration_s=timeout_s)
    finally:
        t.join(timeout_s)
    log = rawlog_path(out)
    start_ns = last_ns = stop_ns = None
    n_bytes = n_reads = 0
    for typ, _stream, host_ns, payload, _ in read_records(log):
        if typ == SESSION:
            start_ns = json.loads(payload)["start_host_ns"]
        elif typ == EVENT and json.loads(payload).get("event") == "stop":
            stop_ns = host_ns
        elif typ == RAW:
            last_ns = host_ns
            n_bytes += len(payload)
            n_reads += 1
    seconds = max(1e-9, (stop_ns - start_ns) / 1e9)
    read_seconds = max(1e-9, (last_ns - start_ns) / 1e9) if last_ns is not None else float("nan")
    return {
        "bytes": n_bytes,
        "bytes_sent": len(data),
        "seconds": seconds,
        "bytes_per_s": n_bytes / seconds,
        "read_bytes_per_s": n_bytes / read_seconds,
        "reads": n_reads,
        "bytes_per_read": n_bytes / max(1, n_reads),
        "rawlog_over_data": log.stat().st_size / max(1, n_bytes),
        "frames": res.stats[0]["frames"],
        "crc_errors": res.stats[0]["crc_errors"],
        "stop": res.reason.split(":")[0],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mbytes", type=float, default=8.0)
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", type=Path, default=RESULTS)
    a = ap.parse_args()
    data, n_frames = board_bytes(int(a.mbytes * 1e6), a.width)
    runs = []
    for _ in range(a.runs):
        with tempfile.TemporaryDirectory() as d:
            r = loopback_capture(data, d)
        r["frames_sent"] = n_frames
        runs.append(r)
        print(f"{r['bytes_per_s'] / 1e6:.2f} MB/s end to end, {r['read_bytes_per_s'] / 1e6:.2f} MB/s read, {r['bytes_per_read']:.0f} B/read, raw log {r['rawlog_over_data']:.3f}x "
              f"the data, {r['frames']}/{n_frames} frames", flush=True)
    best = sorted(runs, key=lambda r: r["bytes_per_s"])[len(runs) // 2]
    result = {
        "what": "capture throughput over a loopback socket (bench/bench_serial.py)",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "loadavg": os.getloadavg()},
        "config": {"mbytes": a.mbytes, "width": a.width, "runs": a.runs},
        "median": best,
        "runs": runs,
        "created_unix_s": time.time(),
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()

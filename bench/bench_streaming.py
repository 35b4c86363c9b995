"""Per-sample latency of the streaming compensators (one sample in, one force out, state carried) on
one CPU core, at the paper's model sizes.

    python bench/bench_streaming.py [--run runs/experiment-cnt_pdms-quick] [--samples 2000]

With --run, the checkpoints of that experiment are timed; otherwise each model is built at its default
(paper) size and fitted for one epoch on a short synthetic sequence (latency does not depend on the
weights). Writes bench/results/streaming-cpu.json. Paper (cnt_pdms Table 3): LSTM 14.8 ms, GRU 10.4 ms,
MLP 2.1 ms; target for ours < 1 ms.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import torch

KINDS = ["linear", "cubic", "mlp", "gru", "lstm", "tcn"]


def _synthetic(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    f = 2.5 * (1 - np.cos(2 * np.pi * 0.5 * t))
    r = 46.3 * np.exp(-0.015 * f) + rng.normal(0, 0.005, n)
    return r[:, None], f[:, None]


def _models(run: Path | None) -> dict:
    from learn.checkpoint import load_checkpoint
    from learn.models import make_model

    if run is not None:
        return {k: load_checkpoint(run / "checkpoints" / k) for k in KINDS if (run / "checkpoints" / k).is_dir()}
    x, y = _synthetic(600)
    out = {}
    for k in KINDS:
        hp = {} if k in ("linear", "cubic") else {"max_epochs": 1, "max_batches_per_epoch": 2}
        out[k] = make_model(k, **hp).fit([x], [y], seed=0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", type=Path, default=None)
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    torch.set_num_threads(1)
    models = _models(a.run)
    x, _ = _synthetic(a.samples + 50, seed=1)
    res = {}
    for k, m in models.items():
        st = m.stream()
        for v in x[:50]:  # warm-up (also fills the window / ring buffers)
            st.step(v)
        ts = np.empty(a.samples)
        ys = []
        for i, v in enumerate(x[50:]):
            t0 = time.perf_counter()
            ys.append(st.step(v))
            ts[i] = time.perf_counter() - t0
        st.reset()
        full = st.run(x)
        diff = float(np.max(np.abs(full - m.predict(x))))
        t0 = time.perf_counter()
        m.predict(x)
        batch = (time.perf_counter() - t0) / len(x)
        res[k] = {"median_ms": 1e3 * float(np.median(ts)), "mean_ms": 1e3 * float(ts.mean()),
                  "p99_ms": 1e3 * float(np.percentile(ts, 99)), "batch_ms_per_sample": 1e3 * batch,
                  "stream_vs_batch_max_abs": diff, "context_samples": m.context, "hparams": m.hparams}
        print(f"{k:7s} stream median {res[k]['median_ms']:.4f} ms  p99 {res[k]['p99_ms']:.4f} ms  "
              f"batch {res[k]['batch_ms_per_sample']:.4f} ms/sample  |stream-batch| {diff:.1e}")
    paper = {"linear": 0.5, "cubic": 0.8, "mlp": 2.1, "gru": 10.4, "lstm": 14.8}
    if "lstm" in res and "tcn" in res:
        print(f"TCN (ours) vs paper LSTM 14.8 ms: {14.8 / res['tcn']['median_ms']:.0f}x faster; "
              f"our LSTM stream {res['lstm']['median_ms']:.3f} ms")
    a.out.mkdir(parents=True, exist_ok=True)
    doc = {"bench": "streaming", "threads": 1, "samples": a.samples, "source": str(a.run) if a.run else "default sizes",
           "machine": {"platform": platform.platform(), "processor": platform.processor(), "torch": torch.__version__},
           "paper_ms": paper, "target_ms": 1.0, "results": res}
    path = a.out / "streaming-cpu.json"
    path.write_text(json.dumps(doc, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

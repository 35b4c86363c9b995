"""The velostat experiment at the full budget on the device machine (driver of bench/device_full_velostat.sh).

  run      one seed: `learn.experiments.velostat.run` (the same run as `piezotwin experiment velostat --seed S`,
           Mode "full" unchanged), the BP hidden-node searches in `--workers` CPU processes (the same nets as one
           after another: tests/test_learn_velostat.py), ours (the TCN ensemble) on `--tcn-device` (auto: CUDA
           where torch sees one); writes <out>/metrics.json (partial while it runs), report.md and
           <out>/run.json (wall and CPU seconds, devices).
  collect  every <run>/seed<S>/metrics.json -> bench/results/experiments/velostat-<mode>.json (seed 0) and
           velostat-<mode>-seed<S>.json, each with the "machine" key docs/gen expects (partial runs keep their
           "partial" key and say so in machine.note).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path


def _cpu_s() -> float:
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def _commit() -> str:
    """The checkout's commit when the run starts (the device copy may have no .git: VF_COMMIT, else unknown)."""
    try:
        r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=20)
        if r.returncode == 0 and r.stdout.strip():
            return r.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return os.environ.get("VF_COMMIT", "unknown")


def cmd_run(a: argparse.Namespace) -> None:
    from learn.experiments import velostat as V
    from learn.train import resolve_device, training_device

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    tcn_dev = resolve_device(a.tcn_device)
    info = {"seed": a.seed, "mode": a.mode, "workers": a.workers, "tcn_workers": a.tcn_workers,
            "tcn_device": tcn_dev, "bp_device": "cpu",
            "overrides": a.set, "started_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "commit": _commit()}
    (out / "run.json").write_text(json.dumps(info, indent=1))

    def log(s: str) -> None:
        print(f"[{time.time() - t0:7.1f} s] {s}", flush=True)

    with training_device("cpu"):  # the paper's BP nets on the CPU (bit-reproducible); ours on tcn_device
        V.run(out, mode=a.mode, overrides=list(a.set), seed=a.seed, progress=False, log=log,
              workers=a.workers, tcn_device=tcn_dev, tcn_workers=a.tcn_workers)
    info.update(wall_s=round(time.time() - t0, 1), cpu_s=round(_cpu_s(), 1), finished=True)
    (out / "run.json").write_text(json.dumps(info, indent=1))
    log(f"done: {info['wall_s']} s wall, {info['cpu_s']} CPU-s")


def _gpu() -> str:
    try:
        r = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                           text=True, timeout=20)
        return r.stdout.strip().replace("\n", ", ") or "none"
    except (OSError, subprocess.SubprocessError):
        return "none"


def cmd_collect(a: argparse.Namespace) -> None:
    run, dest = Path(a.run), Path(a.dest)
    dest.mkdir(parents=True, exist_ok=True)
    gpu = _gpu()
    wrote = []
    for sd in sorted(p for p in run.glob("seed*") if p.is_dir()):
        mp = sd / "metrics.json"
        if not mp.is_file():
            print(f"{sd}: no metrics.json (still generating or training the paper's chains)")
            continue
        m = json.loads(mp.read_text())
        info = json.loads((sd / "run.json").read_text()) if (sd / "run.json").is_file() else {}
        started = info.get("started_utc")
        wall = info.get("wall_s")
        if wall is None and started:  # still running or stopped: up to the last metrics.json written
            wall = round(mp.stat().st_mtime - dt.datetime.fromisoformat(started).timestamp(), 1)
        part = m.get("partial")
        budget = "FULL budget (Mode full unchanged)" if m.get("mode") == "full" else f"mode {m.get('mode')}"
        where = ("run on the device machine by bench/device_full_velostat.sh (seeds side by side, other jobs on the "
                 "same machine)" if a.where == "device" else
                 f"run locally by bench/device_full_velostat.py run (nice 10, {os.cpu_count()} cores shared with other "
                 "helpers' jobs)")
        note = (f"{budget}, seed {m.get('seed')}, {where}: BP hidden "
                f"searches in {info.get('workers', '?')} CPU processes each (torch on one thread: the same nets as "
                f"one after another), ours (TCN ensemble) trained on {info.get('tcn_device', '?')} (GPU: {gpu}; "
                + (f"its input sets side by side in {info['tcn_workers']} processes); " if info.get("tcn_workers", 1) > 1
                   else "its input sets one after another); ") +
                "wall_s / cpu_s = this seed's process from its start, data generation included"
                + (f". PARTIAL: {part}" if part else ""))
        m["machine"] = {"host_platform": platform.platform(), "cpus": os.cpu_count(), "processor": platform.processor(),
                        "gpu": gpu, "git_commit": info.get("commit", a.commit), "date_utc": dt.datetime.now(dt.UTC).date().isoformat(),
                        "wall_s": wall, "cpu_s": info.get("cpu_s"), "train_device_tcn": info.get("tcn_device"),
                        "train_device_bp": "cpu", "note": note}
        s = int(m.get("seed", 0))
        name = f"velostat-{m.get('mode', a.mode)}" + ("" if s == 0 else f"-seed{s}") + ".json"
        if (dest / name).is_file():  # the record this one replaces: the same data (content hashes per folder)?
            try:
                old = json.loads((dest / name).read_text()).get("datasets") or {}
                new = m.get("datasets") or {}
                m["machine"]["datasets_equal_to_replaced_record"] = bool(old) and all(
                    old.get(k, {}).get("content_sha256") == v.get("content_sha256") for k, v in new.items())
                om = json.loads((dest / name).read_text()).get("models") or {}
                both = [k for k in m.get("models", {}) if k in om and k != "tcn"]
                m["machine"]["chains_equal_to_replaced_record"] = {  # the paper's chains: CPU, same seeds
                    k: om[k]["test"]["rmse"] == m["models"][k]["test"]["rmse"] for k in both}
            except (OSError, ValueError, AttributeError):
                pass
        (dest / name).write_text(json.dumps(m, indent=2, allow_nan=True))
        wrote.append(str(dest / name))
        f = m.get("findings", {})
        print(f"{name}: {'PARTIAL' if part else 'complete'}; wall {wall} s; findings keys {len(f)}")
    print("wrote " + (", ".join(wrote) or "nothing"))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--mode", default="full")
    r.add_argument("--out", required=True)
    r.add_argument("--workers", type=int, default=1)
    r.add_argument("--tcn-device", default="auto")
    r.add_argument("--tcn-workers", type=int, default=1, help="processes for ours' input sets (side by side)")
    r.add_argument("--set", action="append", default=[], help="scene override for every folder (key=value)")
    c = sub.add_parser("collect")
    c.add_argument("--run", required=True)
    c.add_argument("--dest", default="bench/results/experiments")
    c.add_argument("--mode", default="full")
    c.add_argument("--commit", default=os.environ.get("VF_COMMIT", "unknown"))
    c.add_argument("--where", choices=("device", "local"), default="device", help="what machine.note says")
    a = ap.parse_args(argv)
    {"run": cmd_run, "collect": cmd_collect}[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())

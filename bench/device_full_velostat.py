"""The velostat experiment at the full budget on the device machine (driver of bench/device_full_velostat.sh).

  run      one seed: `learn.experiments.velostat.run` (the same run as `piezotwin experiment velostat --seed S`,
           Mode "full" unchanged), the BP hidden-node searches in `--workers` CPU processes (the same nets as one
           after another: tests/test_learn_velostat.py), ours (the TCN ensemble) on `--tcn-device` (auto: CUDA
           where torch sees one); writes <out>/metrics.json (partial while it runs), report.md and
           <out>/run.json (wall and CPU seconds, devices).
  collect  every <run>/seed<S>/metrics.json -> bench/results/experiments/velostat-<mode>.json (seed 0) and
           velostat-<mode>-seed<S>.json, each with the "machine" key docs/gen expects (partial runs keep their
           "partial" key and say so in machine.note).
  run --ours-only   ours (the TCN seed ensembles, every member of every input set as one batched network) and only
           what its inputs need (data, creep tracker, units, the BP chains raw_bp and paper_unit), with the data's
           shards made in --gen-workers processes (the same data: content hashes)
  merge    every <run>/seed<S>/metrics.json of an --ours-only run -> INTO the recorded velostat-<mode>[-seedS].json:
           refused (exit 3, that record untouched) unless the data are the record's (per folder content_sha256 and
           config_sha256) and the split is the record's; then models.tcn is ours, the findings are recomputed from
           the recorded chains and ours, "partial" is dropped, and machine.ours records the run (commit, GPU,
           timings, the re-fitted chains against the recorded ones); the paper's chains stay as recorded.
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
            "commit": _commit(), "gen_workers": a.gen_workers, "ours_only": bool(a.ours_only)}
    (out / "run.json").write_text(json.dumps(info, indent=1))
    stages: dict[str, float] = {}  # when each stage's log line came (s from the start), for the record

    def log(s: str) -> None:
        stages[s.split(":")[0][:60]] = round(time.time() - t0, 1)
        print(f"[{time.time() - t0:7.1f} s] {s}", flush=True)

    with training_device("cpu"):  # the paper's BP nets on the CPU (bit-reproducible); ours on tcn_device
        V.run(out, mode=a.mode, overrides=list(a.set), seed=a.seed, progress=False, log=log,
              workers=a.workers, tcn_device=tcn_dev, tcn_workers=a.tcn_workers, gen_workers=a.gen_workers,
              ours_only=a.ours_only)
    info.update(stages_s=stages, wall_s=round(time.time() - t0, 1), cpu_s=round(_cpu_s(), 1), finished=True)
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


def merge_ours(rec: dict, new: dict, info: dict, gpu: str, commit: str) -> dict:
    """The recorded run `rec` with ours from the --ours-only run `new` of the same data; ValueError when the data
    or the split differ (nothing merged)."""
    from learn.experiments.velostat import findings

    if not new.get("ours_only") or "tcn" not in new.get("models", {}):
        raise ValueError("not a finished --ours-only run (no ours in its metrics.json)")
    for k in ("experiment", "mode", "seed"):
        if rec.get(k) != new.get(k):
            raise ValueError(f"{k}: recorded {rec.get(k)!r}, this run {new.get(k)!r}")
    rd, nd = rec.get("datasets") or {}, new.get("datasets") or {}
    if set(rd) != set(nd):
        raise ValueError(f"data folders: recorded {sorted(rd)}, this run {sorted(nd)}")
    for f in rd:
        for h in ("content_sha256", "config_sha256"):
            if not rd[f].get(h) or rd[f].get(h) != nd[f].get(h):
                raise ValueError(f"data {f}: {h} {nd[f].get(h)} differs from the record's {rd[f].get(h)}")
    if rec.get("split") != new.get("split"):
        raise ValueError("the split (episode keys of train / valid / test) differs from the record's")
    out = json.loads(json.dumps(rec))
    out["models"]["tcn"] = new["models"]["tcn"]
    out["findings"] = findings(out["models"], out["creep"], out["clustering"], out.get("bp_search"))
    part = out.pop("partial", None)
    out["run"] = {**out.get("run", {}), "tcn_device": new["run"].get("tcn_device"),
                  "tcn_batched": new["run"].get("tcn_batched"), "tcn_workers": new["run"].get("tcn_workers")}
    # the chains ours' inputs read were fitted again in the ours-only run: the same nets as recorded?
    chains = {}
    for k, v in new["models"].items():
        if k == "tcn" or k not in rec["models"]:
            continue
        a, b = rec["models"][k]["test"], v["test"]
        chains[k] = {"equal": a == b, "rmse_recorded": a.get("rmse"), "rmse_refitted": b.get("rmse")}
    bp_h = {k: [rec.get("bp_search", {}).get(k, {}).get("best_hidden"), v.get("best_hidden")]
            for k, v in new.get("bp_search", {}).items()}
    ours = {"git_commit": info.get("commit", commit), "gpu": gpu, "date_utc": dt.datetime.now(dt.UTC).date().isoformat(),
            "wall_s": info.get("wall_s"), "cpu_s": info.get("cpu_s"), "train_device_tcn": info.get("tcn_device"),
            "fit_seconds": new["models"]["tcn"].get("fit_seconds"), "stages_s": info.get("stages_s"),
            "gen_workers": info.get("gen_workers"), "bp_workers": info.get("workers"),
            "datasets_equal_to_record": True, "split_equal_to_record": True,
            "chains_refitted_vs_record": chains, "bp_best_hidden_recorded_vs_refitted": bp_h,
            "replaced_partial": part}
    m = out.setdefault("machine", {})
    m["ours"] = ours
    same = all(c["equal"] for c in chains.values())
    m["note"] = (m.get("note", "").split(". PARTIAL:")[0]
                 + f". OURS (TCN) merged from a later run of the same data (bench/device_full_velostat.sh with "
                 f"VF_ONLY=ours, commit {ours['git_commit']}, {gpu}): every member of its input sets trained as one "
                 f"batched network on {info.get('tcn_device')}; its inputs' chains (" + ", ".join(chains)
                 + (") fitted again equal the recorded ones" if same else
                    ") fitted again differ from the recorded ones in float rounding (machine.ours.chains_refitted_vs_record)")
                 + "; the paper's chains, diagnostics and timings above are the record's")
    return out


def cmd_merge(a: argparse.Namespace) -> int:
    run, dest = Path(a.run), Path(a.dest)
    gpu = _gpu()
    seeds = sorted(p for p in run.glob("seed*") if p.is_dir())
    bad = 0 if seeds else 1
    if not seeds:
        print(f"{run}: no seed folders (wrong VF_RUN?)")
    for sd in seeds:
        mp = sd / "metrics.json"
        if not mp.is_file():
            print(f"{sd}: no metrics.json yet")
            bad += 1
            continue
        new = json.loads(mp.read_text())
        info = json.loads((sd / "run.json").read_text()) if (sd / "run.json").is_file() else {}
        if not info.get("finished"):  # run.json is marked finished just before the log's "done"
            print(f"{sd}: not finished (run.json has no finished mark): refused; the record is untouched")
            bad += 1
            continue
        s = int(new.get("seed", 0))
        name = f"velostat-{new.get('mode', a.mode)}" + ("" if s == 0 else f"-seed{s}") + ".json"
        if not (dest / name).is_file():
            print(f"{name}: no record to merge into: refused")
            bad += 1
            continue
        try:
            merged = merge_ours(json.loads((dest / name).read_text()), new, info, gpu, a.commit)
        except ValueError as e:
            print(f"{name}: REFUSED ({e}); the record is untouched")
            bad += 1
            continue
        (dest / name).write_text(json.dumps(merged, indent=2, allow_nan=True))
        t = merged["models"]["tcn"]
        print(f"{name}: ours merged (test RMSE {t['test']['rmse']:.3f} N, inputs {t.get('inputs')}, fit "
              f"{t.get('fit_seconds', 0):.0f} s); beats every paper chain on every metric: "
              f"{merged['findings'].get('ours_beats_every_paper_model_on_every_metric')}")
    return 3 if bad else 0


def main(argv: list[str] | None = None) -> int:
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
    r.add_argument("--gen-workers", type=int, default=1, help="processes for each data folder's shards")
    r.add_argument("--ours-only", action="store_true", help="ours and what its inputs need (to merge into a record)")
    g = sub.add_parser("merge")
    g.add_argument("--run", required=True)
    g.add_argument("--dest", default="bench/results/experiments")
    g.add_argument("--mode", default="full")
    g.add_argument("--commit", default=os.environ.get("VF_COMMIT", "unknown"))
    c = sub.add_parser("collect")
    c.add_argument("--run", required=True)
    c.add_argument("--dest", default="bench/results/experiments")
    c.add_argument("--mode", default="full")
    c.add_argument("--commit", default=os.environ.get("VF_COMMIT", "unknown"))
    c.add_argument("--where", choices=("device", "local"), default="device", help="what machine.note says")
    a = ap.parse_args(argv)
    return {"run": cmd_run, "collect": cmd_collect, "merge": cmd_merge}[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())

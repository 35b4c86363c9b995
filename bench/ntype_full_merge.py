"""Merge the ntype full run's per-process metrics (bench/device_full_ntype.sh collect) into one results file per
seed, bench/results/experiments/<prefix>.json (seed 0), <prefix>-seed1.json, <prefix>-seed2.json: the shape of
`piezotwin experiment ntype`'s metrics.json (learn.experiments.ntype.merge_runs) plus a "machine" key.

A model group whose process did not finish is taken from the recorded paper-methods file of that seed
(--recorded, e.g. ntype-full-paper.json: Table 1 and window 5 of session 9) only when that file ran on the same
data (content_sha256) and folds; otherwise it is left out and listed under machine.missing.

  python3 bench/ntype_full_merge.py --root runs/ntype-full-dev --seeds 0,1,2
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
from pathlib import Path


def _git() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except Exception:  # noqa: BLE001  (a copy of the tree without .git)
        return "?"


def merge_seed(root: Path, seed: int, recorded: Path | None, expected: list[str]) -> tuple[dict, dict]:
    from learn.experiments.ntype import _content, merge_runs

    parts, infos, missing = [], [], []
    for name in expected:
        d = root / "parts" / f"s{seed}-{name}" / "out"
        info = json.loads((d / "run_info.json").read_text()) if (d / "run_info.json").exists() else {"status": "not finished"}
        info["part"] = name
        infos.append(info)
        if info.get("status") == "done" and (d / "metrics.json").exists():
            m = json.loads((d / "metrics.json").read_text())
            m["run"] = {k: info.get(k) for k in ("train_device", "gpu", "cpu_s", "wall_s", "threads")}
            parts.append(m)
        else:
            missing.append(name)
    if not parts:
        raise SystemExit(f"seed {seed}: no part finished ({', '.join(missing)})")
    used_recorded = []
    if missing and recorded is not None and recorded.exists():
        r = json.loads(recorded.read_text())
        if (_content(r) == _content(parts[0])
                and r["protocol"]["fold_episodes"] == parts[0]["protocol"]["fold_episodes"]):
            have = {k for m in parts for k in m["models"] if k != "mean"}
            have_w = {w for m in parts for w in m["models"].get("rbf_win", {})}
            take = {k: v for k, v in r["models"].items() if k not in have and k not in ("mean", "rbf_win")}
            win = {w: v for w, v in r["models"].get("rbf_win", {}).items() if w not in have_w}
            if take or win:
                models = {"mean": r["models"]["mean"], **take, **({"rbf_win": win} if win else {})}
                keep_f = {k: r["findings"][k] for k in ("nearest_centre_median", "table1_exact_phi_condition_fold1")
                          if k in r["findings"]}
                parts.append({**r, "models": models, "findings": keep_f,
                              "protocol": {**r["protocol"], "windows": [int(w) for w in win]},
                              "timing_s": {}, "run": {"recorded": recorded.name}})
                used_recorded = sorted(take) + [f"rbf_w{w}" for w in win]
    m = merge_runs(parts)
    return m, {"parts": infos, "missing": missing, "from_recorded": used_recorded}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", type=Path, required=True)
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--parts", required=True, help="the part names that were launched (comma-separated)")
    ap.add_argument("--results", type=Path, default=Path("bench/results/experiments"))
    ap.add_argument("--prefix", default="ntype-full")
    ap.add_argument("--recorded-prefix", default="ntype-full-paper", help="fallback files (same dataset only)")
    ap.add_argument("--wall-s", type=float, default=None, help="the whole run's wall time (start to last part)")
    a = ap.parse_args()
    from learn.data import dumps

    names = [p for p in a.parts.split(",") if p]
    a.results.mkdir(parents=True, exist_ok=True)
    for seed in (int(s) for s in a.seeds.split(",")):
        suffix = "" if seed == 0 else f"-seed{seed}"
        rec = a.results / f"{a.recorded_prefix}{suffix}.json"
        m, run = merge_seed(a.root, seed, rec, names)
        infos = run["parts"]
        devs = sorted({i.get("train_device") for i in infos if i.get("status") == "done" and
                       set(i.get("models", [])) & {"elem_mlp", "map_cnn"}} - {None})
        gpus = sorted({i.get("gpu") for i in infos if i.get("gpu")})
        m["machine"] = {
            "host_platform": platform.platform(), "cpus": infos[0].get("cpus"), "git_commit": _git(),
            "date_utc": __import__("datetime").datetime.now(__import__("datetime").timezone.utc).strftime("%Y-%m-%d"),
            "cpu_s": round(sum(float(i.get("cpu_s", 0.0)) for i in infos), 1),
            "wall_s": a.wall_s, "train_device": devs, "gpu": gpus,
            "parts": "; ".join(
                f"{i['part']} {i.get('status')}" + (f" {float(i['cpu_s']):.0f} CPU-s / {float(i['wall_s']):.0f} s wall"
                                                    if i.get("cpu_s") is not None else "")
                + (f" ({i.get('train_device')})" if set(i.get("models", [])) & {"elem_mlp", "map_cnn"} else "")
                for i in infos),
            "missing": run["missing"], "from_recorded": run["from_recorded"],
            "note": ("device full run (bench/device_full_ntype.sh): the paper's task at the full budget (MODES['full'], "
                     "3000 samples, 10 folds), one process per model group / window, merged by "
                     "learn.experiments.ntype.merge_runs; press_stroke not run at full (time)"
                     + (f"; not finished: {', '.join(run['missing'])}" if run["missing"] else "")
                     + (f"; taken from {a.recorded_prefix}{suffix}.json (same dataset and folds): "
                        + ", ".join(run["from_recorded"]) if run["from_recorded"] else "")),
        }
        out = a.results / f"{a.prefix}{suffix}.json"
        out.write_text(dumps(m))
        F = m["findings"]
        print(f"{out}: parts done {len(infos) - len(run['missing'])}/{len(infos)}; best paper model "
              f"{F.get('best_paper_model')} {F.get('best_paper_errors')}; elem_mlp "
              f"{ {c: m['models']['elem_mlp'][f'E_{c}'] for c in ('Fx', 'Fy', 'Fz')} if 'elem_mlp' in m['models'] else '-'}; "
              f"table1 best {F.get('table1_best_spread')}; w5 beats none {F.get('window5_beats_no_window')}; "
              f"ours beats {F.get('elem_mlp_beats_best_paper_model')}", flush=True)


if __name__ == "__main__":
    main()

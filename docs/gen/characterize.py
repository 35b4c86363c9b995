"""Run `piezotwin characterize` on every preset and write its table, notes and numbers as JSON.

    python docs/gen/characterize.py                  # every preset -> bench/results/characterize-<preset>.json
    python docs/gen/characterize.py cnt_pdms fabric_1 # some presets

The docs generator (docs/gen/generate.py) renders these files on the family pages; a family whose file is
missing says "not run yet". Rerun this after a physics change (it takes a few minutes on 2 cores:
velostat runs through MuJoCo)."""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results"
if str(ROOT) not in sys.path:  # run from anywhere, installed or not
    sys.path.insert(0, str(ROOT))


def presets() -> list[str]:
    return sorted(p.stem for p in (ROOT / "scenes" / "presets").glob("*.yaml"))


def machine() -> dict:
    import os

    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = ""
    return {"host_platform": platform.platform(), "cpus": os.cpu_count(), "processor": platform.processor(),
            "git_commit": commit, "date_utc": datetime.now(UTC).strftime("%Y-%m-%d")}


def run(preset: str) -> Path:
    from scenes import load_scene
    from sensors.warp_setup import init_warp
    from simulate.characterize import characterize

    init_warp()
    cfg = load_scene(preset, [])
    t0 = time.perf_counter()
    rep = characterize(cfg)
    out = {"preset": preset, "family": cfg.sensor.family, "title": rep.title, "columns": rep.columns, "rows": rep.rows,
           "notes": rep.notes, "metrics": rep.metrics, "seconds": round(time.perf_counter() - t0, 1), "machine": machine()}
    path = RESULTS / f"characterize-{preset}.json"
    path.write_text(json.dumps(out, indent=1, default=float) + "\n")
    print(f"wrote {path} ({out['seconds']} s)")
    return path


if __name__ == "__main__":
    for p in sys.argv[1:] or presets():
        run(p)

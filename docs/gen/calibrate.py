"""Run `piezotwin calibrate FAMILY` (without --write) and record its targets beside its results as JSON.

    python docs/gen/calibrate.py velostat      # -> bench/results/calibrate-velostat.json

The docs generator (docs/gen/generate.py) renders each recorded file as docs/_generated/calibrate-<family>.md,
included on the family page. Rerun after a physics change (and `piezotwin calibrate FAMILY --write`)."""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def run(family: str) -> Path:
    from characterize import machine

    from piezotwin.cmd_calibrate import CALIBRATIONS

    module, fn = CALIBRATIONS[family].split(":")
    t0 = time.perf_counter()
    res = getattr(importlib.import_module(module), fn)()
    out = {"family": family, "command": f"piezotwin calibrate {family}",
           "rows": [{"name": r.name, "target": r.target, "result": r.result, "unit": r.unit, "met": r.met} for r in res.rows],
           "notes": list(res.notes),
           "preset_fields": {str(Path(p).relative_to(ROOT)) if Path(p).is_relative_to(ROOT) else p: f
                             for p, f in res.preset_fields.items()},
           "seconds": round(time.perf_counter() - t0, 1), "machine": machine()}
    path = RESULTS / f"calibrate-{family}.json"
    path.write_text(json.dumps(out, indent=1, default=float) + "\n")
    print(f"wrote {path} ({out['seconds']} s)")
    return path


if __name__ == "__main__":
    for f in sys.argv[1:]:
        run(f)

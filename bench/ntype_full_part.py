"""One process of the ntype full run on the device machine (bench/device_full_ntype.sh): one seed, one model
group of the paper's task (`learn.experiments.ntype.run` with MODES[mode] narrowed to tasks=("paper",), the
windows and Table 1 readings given here), on data already generated into --data. Writes <out>/metrics.json
(the experiment's own) and <out>/run_info.json (CPU and wall seconds, thread settings, the torch device of the
gradient-trained nets, GPU name).

  python3 bench/ntype_full_part.py --seed 0 --models rbf_win --windows 3 --out runs/x --data runs/d/s0
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import resource
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--models", required=True, help="comma-separated: rbf_col, rbf_win, elem_mlp, map_cnn")
    ap.add_argument("--windows", default="1,3,5,7", help="rbf_win's windows in this process")
    ap.add_argument("--alts", default="eq9+exact", help="Table 1's other readings (comma-separated; '' = none)")
    ap.add_argument("--mode", default="full", help="full (the budget) | tiny (tests of the script)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--data", type=Path, required=True, help="folder holding <task>/ (made or reused)")
    ap.add_argument("--train-device", default="cpu", help="cpu | cuda | auto: where elem_mlp and map_cnn train")
    ap.add_argument("--centres-win", type=int, default=None, help="the window networks' k-means centres (default: the mode's)")
    a = ap.parse_args()

    import torch

    from learn.experiments import ntype as NT
    from learn.train import resolve_device, training_device

    torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "1")))
    alts = tuple(x for x in a.alts.split(",") if x)
    wins = tuple(int(w) for w in a.windows.split(",") if w)
    NT.MODES[a.mode] = dataclasses.replace(NT.MODES[a.mode], tasks=("paper",), alt_kernels=alts, windows=wins,
                                           **({} if a.centres_win is None else {"centres_win": a.centres_win}))
    dev = resolve_device(a.train_device)
    t0, c0 = time.perf_counter(), time.process_time()
    a.out.mkdir(parents=True, exist_ok=True)
    info = {"seed": a.seed, "models": a.models.split(","), "windows": list(wins), "alt_kernels": list(alts),
            "centres_win": NT.MODES[a.mode].centres_win,
            "mode": a.mode, "train_device": dev, "threads": torch.get_num_threads(),
            "omp_num_threads": os.environ.get("OMP_NUM_THREADS"), "host": platform.node(), "cpus": os.cpu_count(),
            "torch": torch.__version__, "gpu": torch.cuda.get_device_name(0) if dev.startswith("cuda") else None,
            "status": "failed"}
    try:
        with training_device(dev):
            NT.run(a.out, mode=a.mode, data_dir=a.data, models=a.models.split(","), seed=a.seed, progress=False,
                   log=lambda s: print(s, flush=True))
        info["status"] = "done"
    finally:
        ru = resource.getrusage(resource.RUSAGE_SELF)
        info.update({"wall_s": time.perf_counter() - t0, "cpu_s": ru.ru_utime + ru.ru_stime, "user_s": ru.ru_utime,
                     "sys_s": ru.ru_stime, "process_cpu_s": time.process_time() - c0})
        (a.out / "run_info.json").write_text(json.dumps(info, indent=1))
        print("run_info", json.dumps(info), flush=True)


if __name__ == "__main__":
    main()

"""The CPU path against an earlier commit, in one run: the plain CLI on C MuJoCo at both revisions, interleaved.

    python bench/bench_cpu_ab.py --base fb174ae [--families cnt_pdms,fabric_1,velostat,ntype] [--episodes 8]
                                 [--timed-family cnt_pdms] [--timed-episodes 64] [--repeats 3] [--tag cpu-s9]

For every family, `piezotwin generate FAMILY --physics mujoco --device cpu --workers 1` at both revisions and the
manifests' content hashes compared (same data: the CPU path's bytes did not change). For the timed family, the wall
time of both revisions, interleaved `repeats` times (the order alternates), so machine load hits both alike.
The base revision runs from a temporary `git worktree`. Writes bench/results/cpu-ab-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def generate(src: Path, family: str, out: Path, episodes: int) -> tuple[float, str, float]:
    """Wall seconds of the CLI run, its manifest's content hash and the CPU seconds (user + system) of the run's
    processes (robust to other jobs on a shared machine, where the wall time is not)."""
    env = {**os.environ, "PYTHONPATH": str(src), "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "piezotwin", "generate", family, "-o", str(out), "--episodes", str(episodes),
           "--physics", "mujoco", "--device", "cpu", "--workers", "1"]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, cwd=src, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    dt = time.perf_counter() - t
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return dt, json.loads((out / "manifest.json").read_text())["content_sha256"], cpu


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", required=True, help="the earlier commit")
    ap.add_argument("--families", default="cnt_pdms,fabric_1,velostat,ntype")
    ap.add_argument("--episodes", type=int, default=8)
    ap.add_argument("--timed-family", default="cnt_pdms")
    ap.add_argument("--timed-episodes", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", default="cpu")
    a = ap.parse_args()
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "-q", "--detach", str(base), a.base], cwd=ROOT, check=True)
        try:
            revs = {"base": base, "head": ROOT}
            same = {}
            for fam in a.families.split(","):
                h = {k: generate(src, fam, Path(tmp) / f"{fam}-{k}", a.episodes)[1] for k, src in revs.items()}
                same[fam] = {"base": h["base"], "head": h["head"], "equal": h["base"] == h["head"]}
                print(f"{fam}: content hash {'equal' if h['base'] == h['head'] else 'DIFFERS'}")
            times: dict[str, list[float]] = {"base": [], "head": []}
            cpus: dict[str, list[float]] = {"base": [], "head": []}
            for r in range(a.repeats):
                for k in (("head", "base") if r % 2 == 0 else ("base", "head")):
                    out = Path(tmp) / f"t-{k}-{r}"
                    wall, _, cpu = generate(revs[k], a.timed_family, out, a.timed_episodes)
                    times[k].append(wall)
                    cpus[k].append(cpu)
                    subprocess.run(["rm", "-rf", str(out)], check=True)
                print(f"repeat {r}: base {times['base'][-1]:.1f} s ({cpus['base'][-1]:.1f} CPU-s), head {times['head'][-1]:.1f} s "
                      f"({cpus['head'][-1]:.1f} CPU-s)")
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, check=False)
    res = {"host": platform.node(), "cpus": os.cpu_count(), "base": a.base, "head": head,
           "same_content": same, "timed": {"family": a.timed_family, "episodes": a.timed_episodes,
                                            "seconds": times, "min_s": {k: min(v) for k, v in times.items()},
                                            "head_over_base_min": min(times["head"]) / min(times["base"]),
                                            "cpu_seconds": cpus, "cpu_min_s": {k: min(v) for k, v in cpus.items()},
                                            "head_over_base_cpu_min": min(cpus["head"]) / min(cpus["base"])},
           "loadavg_at_end": list(os.getloadavg())}
    out = ROOT / "bench" / "results" / f"cpu-ab-{a.tag}.json"
    out.write_text(json.dumps(res, indent=1) + "\n")
    print(f"head / base, best of {a.repeats}: wall {res['timed']['head_over_base_min']:.3f}, CPU "
          f"{res['timed']['head_over_base_cpu_min']:.3f}; wrote {out}")


if __name__ == "__main__":
    main()

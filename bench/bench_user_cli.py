"""The plain CLI as a user types it: `piezotwin generate <family> -o X --episodes N` with defaults (auto engine,
device, workers, compression), timed from the shell, against a plain file of the same number of bytes written to
the same disk right after (fsync'd), in one run.

    python bench/bench_user_cli.py [--families cnt_pdms,fabric_1,velostat,ntype] [--episodes 4096,64,256,2048] [--tag h100]

Per family: wall seconds, samples/s, MB/s of the dataset, raw MB/s of the same bytes, their ratio, and the CLI's
`engine:` line (which engine and device ran, and why). Writes bench/results/user-cli-<tag>.json with the GPU named.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def gpu_name() -> str:
    try:
        return subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                              text=True, timeout=30).stdout.strip() or "none"
    except (OSError, subprocess.SubprocessError):
        return "none"


def raw_write(nbytes: int, where: Path) -> float:
    """MB/s of one plain file of nbytes (in 64 MB blocks), fsync'd."""
    block = os.urandom(1 << 20) * 64
    t0 = time.perf_counter()
    with open(where / "raw.bin", "wb") as f:
        left = nbytes
        while left > 0:
            f.write(block[: min(left, len(block))])
            left -= len(block)
        f.flush()
        os.fsync(f.fileno())
    dt = time.perf_counter() - t0
    (where / "raw.bin").unlink()
    return nbytes / dt / 1e6


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--families", default="cnt_pdms,fabric_1,velostat,ntype")
    ap.add_argument("--episodes", default="4096,64,256,2048")
    ap.add_argument("--extra", default="", help="more CLI arguments for every run, e.g. '--physics mujoco'")
    ap.add_argument("--tag", default="local")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    ap.add_argument("--scratch", type=Path, default=None, help="where the datasets go (default: a temp dir beside results)")
    ap.add_argument("--timeout", type=float, default=None, help="seconds per CLI run (killed past it; recorded as an error)")
    a = ap.parse_args()
    fams, eps = a.families.split(","), [int(x) for x in a.episodes.split(",")]
    res = {"host": platform.node(), "cpus": os.cpu_count(), "gpu": gpu_name(), "extra": a.extra, "runs": {}}
    scratch = a.scratch or a.out.parent
    for fam, n in zip(fams, eps):
        with tempfile.TemporaryDirectory(dir=scratch) as tmp:
            out = Path(tmp) / "ds"
            cmd = [sys.executable, "-m", "piezotwin.cli", "generate", fam, "-o", str(out), "--episodes", str(n)] + a.extra.split()
            timings = Path(tmp) / "timings.json"
            env = {**os.environ, "PIEZOTWIN_TIMINGS_JSON": str(timings), "PIEZOTWIN_T0_WALL": repr(time.time())}
            t0 = time.perf_counter()
            try:
                p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=a.timeout)
            except subprocess.TimeoutExpired as exc:
                res["runs"][fam] = {"episodes": n, "error": f"killed after {exc.timeout} s"}
                print(f"{fam}: killed after {exc.timeout} s")
                _save(res, a)
                continue
            wall = time.perf_counter() - t0
            line = next((ln for ln in p.stdout.splitlines() if ln.startswith("engine:")), "")
            if p.returncode != 0:
                res["runs"][fam] = {"episodes": n, "error": (p.stderr or p.stdout)[-2000:]}
                print(f"{fam}: failed\n{p.stderr[-2000:]}")
                _save(res, a)
                continue
            m = json.loads((out / "manifest.json").read_text())
            nbytes = sum(f.stat().st_size for f in out.glob("*.h5"))
            samples = None
            try:
                sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
                from sensors.data.recording import Recording

                samples = 0
                for f in sorted(out.glob("*.h5")):
                    with Recording(f) as rec:
                        samples += sum(int(rec.episode_attrs(e)["n_samples"]) for e in rec.episode_ids)
            except Exception as exc:  # noqa: BLE001 - the count is optional
                print(f"  (samples not counted: {exc})")
            shutil.rmtree(out)
            raw = raw_write(nbytes, Path(tmp))
            r = {"episodes": n, "shards": len(m["shards"]), "seconds": wall, "file_bytes": nbytes, "MB_per_s": nbytes / wall / 1e6,
                 "raw_MB_per_s_same_bytes": raw, "of_raw": nbytes / wall / 1e6 / raw, "engine_line": line}
            if samples:
                r.update(samples=samples, samples_per_s=samples / wall)
            if timings.exists():  # seconds per stage, from the CLI process (start-up, first batch, drain, manifest)
                r["timings"] = json.loads(timings.read_text())
                cli = r["timings"].get("cli", {})
                if "dumped at (from process start)" in cli:  # the process's exit (teardown) = wall - its last write
                    cli["exit (after the last write)"] = wall - cli["dumped at (from process start)"]
                    print("  cli: " + ", ".join(f"{k} {v:.2f} s" for k, v in cli.items()))
            res["runs"][fam] = r
            print(f"{fam}: {n} episodes in {wall:.1f} s, {r.get('samples_per_s', 0):.3g} samples/s, {r['MB_per_s']:.0f} MB/s "
                  f"({r['of_raw']:.0%} of raw {raw:.0f} MB/s)\n  {line}")
            if "timings" in r:
                print("  " + "; ".join(f"{k} {v:.1f}{'' if '(a size' in k else ' s'}" for part in r["timings"].values()
                                       for k, v in part.items()))
            _save(res, a)
    print(f"wrote {_save(res, a)}")


def _save(res: dict, a: argparse.Namespace) -> Path:
    """The results so far (after each family, so a run stopped midway keeps what it measured)."""
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"user-cli-{a.tag}.json"
    path.write_text(json.dumps(res, indent=2))
    return path


if __name__ == "__main__":
    main()

"""End-to-end generation speed, stage by stage, in one run: MuJoCo rollout + load field, sensor chain
(Warp vs numpy reference), HDF5 write (vs the raw bytes written uncompressed), on the default preset.

    python bench/bench_pipeline.py [--episodes 16] [--frequency 0.5]

Writes bench/results/pipeline-<device>.json. "Sensor samples" = one 100 Hz frame of one episode (all
taxels and channels, with labels).
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--frequency", type=float, default=0.5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()

    from scenes import config_json, load_scene
    from sensors.cnt_pdms.model import CntPdmsSensor
    from sensors.data.recording import write_recording
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field import run_episodes
    from simulate.generation.run import channel_arrays, episode_channels
    from simulate.protocols.indenter import make_episode_protocol

    init_warp()
    cfg = load_scene("cnt_pdms", [f"protocol.frequencies_hz=[{a.frequency}]"])
    protos = [make_episode_protocol(cfg, s) for s in range(a.episodes)]
    T = protos[0].n_samples
    samples = a.episodes * T
    res: dict = {"host": platform.node(), "episodes": a.episodes, "samples_per_episode": T, "taxels": cfg.pad.n_taxels}

    t0 = time.perf_counter()
    batch = run_episodes(cfg, protos, threads=a.threads)
    t_mj = time.perf_counter() - t0
    steps = samples * cfg.sampling.substeps
    res["mujoco"] = {"seconds": t_mj, "episodes_per_s": a.episodes / t_mj, "physics_steps_per_s": steps / t_mj,
                     "threads": a.threads}

    sens = {}
    for backend in ("numpy", "warp"):
        s = CntPdmsSensor(cfg, backend=backend, device=a.device if backend == "warp" else "cpu")
        drive = s.drive_from_load(batch.deformation_m, batch.pressure_pa)
        s.run(drive[:1, :10], [0])  # compile / warm up
        t0 = time.perf_counter()
        out = s.run_load(batch, list(range(a.episodes)))
        sens[backend] = time.perf_counter() - t0
    res["sensor"] = {k: {"seconds": v, "samples_per_s": samples / v} for k, v in sens.items()}

    arrays = channel_arrays(batch, out, cfg, s)
    eps = {f"ep-{j}": episode_channels(arrays, j) for j in range(a.episodes)}
    raw = sum(c.data.nbytes for e in eps.values() for c in e.values())
    with tempfile.TemporaryDirectory() as tmp:
        times = {}
        for comp in ("none", "lzf"):
            t0 = time.perf_counter()
            p = write_recording(Path(tmp) / f"{comp}.h5", eps, source="sim", config_json=config_json(cfg), root_seed=0,
                                shard_index=0, sensor_attrs={"family": "cnt_pdms"}, compression=comp)
            times[comp] = (time.perf_counter() - t0, p.stat().st_size)
        t0 = time.perf_counter()
        blob = np.concatenate([c.data.reshape(-1).view(np.uint8) for e in eps.values() for c in e.values()])
        with open(Path(tmp) / "raw.bin", "wb") as f:
            f.write(blob.tobytes())
        t_raw = time.perf_counter() - t0
    res["write"] = {
        "raw_bytes": raw,
        "plain_file_MB_per_s": raw / t_raw / 1e6,
        **{f"hdf5_{k}": {"seconds": v[0], "MB_per_s": raw / v[0] / 1e6, "file_bytes": v[1]} for k, v in times.items()},
    }
    total = t_mj + sens["warp"] + times["lzf"][0]
    res["end_to_end"] = {"seconds": total, "samples_per_s": samples / total,
                         "share": {"mujoco": t_mj / total, "sensor_warp": sens["warp"] / total, "write_lzf": times["lzf"][0] / total}}

    print(f"{a.episodes} episodes x {T} samples ({cfg.pad.n_taxels} taxels), f = {a.frequency} Hz, {a.threads} threads")
    print(f"MuJoCo rollout + load field: {t_mj:.2f} s = {a.episodes / t_mj:.2f} episodes/s ({steps / t_mj:.3g} physics steps/s)")
    print(f"sensor chain: numpy {sens['numpy']:.2f} s, warp {sens['warp']:.2f} s  (warp/numpy speed-up {sens['numpy'] / sens['warp']:.1f}x)")
    print(f"write {raw / 1e6:.0f} MB: plain file {res['write']['plain_file_MB_per_s']:.0f} MB/s, HDF5 none "
          f"{res['write']['hdf5_none']['MB_per_s']:.0f} MB/s, lzf {res['write']['hdf5_lzf']['MB_per_s']:.0f} MB/s "
          f"(file {times['lzf'][1] / raw:.2f}x raw)")
    sh = res["end_to_end"]["share"]
    print(f"end to end: {samples / total:.0f} sensor samples/s; time share mujoco {sh['mujoco']:.0%}, "
          f"sensor {sh['sensor_warp']:.0%}, write {sh['write_lzf']:.0%}")
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"pipeline-{'gpu' if a.device != 'cpu' else 'cpu'}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

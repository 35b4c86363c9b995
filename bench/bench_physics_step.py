"""The largest physics step per family that keeps the contact force within 0.5 % of full scale of a 1 ms reference.

    python bench/bench_physics_step.py [--families fabric_1,velostat,ntype,cnt_pdms] [--episodes 8]
                                       [--steps-ms 5,7.14,7.69 --tag=-check32]   (a subset, e.g. with more episodes)

The physics step is the model's time step (`sampling.physics_timestep_s`): it also sets the indenter's armature
and the servo gains (`simulate.contact.mjcf.contact_design`: sqrt(k / m) dt = SERVO_OMEGA_DT), so a step is a
model, and the same model runs on C MuJoCo and on MuJoCo Warp (their contact forces agree within 3e-5 of full
scale: tests/test_contact_mjw.py). The study therefore runs on C MuJoCo (float64, on the CPU): per family, the
same episodes (the preset's default protocol, seeds 0..N-1) at every step that divides the sample period, and
the net contact force at the sample times against the 1 ms run. Full scale: the protocol's largest commanded
force (`protocol.amplitude_max`, force control) or the reference's largest |force| (displacement control).
Acceptance (issue 16): max |F_dt - F_1ms| <= 0.5 % of full scale over every episode, sample and axis.

Writes bench/results/physics-step-<family>.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

REFERENCE_S = 1e-3
TOLERANCE = 5e-3  # of full scale (issue 16)
CANDIDATES_MS = (1.0, 2.0, 2.5, 4.0, 5.0, 10.0, 12.5, 20.0, 25.0, 50.0)
# and the sample period / k for k = 10-20 (at 10 Hz: 10, 9.09, 8.33, 7.69, 7.14, 6.67, 6.25, 5.88, 5.56, 5.26, 5 ms):
# the steps between 5 and 10 ms that still divide the period, so "the largest step within tolerance" is not only
# the largest round one (session 24)
PERIOD_DIVISORS = range(10, 21)


def contact_forces(cfg, protos) -> np.ndarray:
    """(sum of T_e, 3) net contact force on the pad at the sample times of every episode, episodes one after
    another (x, y tangential, z compressive); episodes of one length run as one batch."""
    from simulate.contact.load_field import (
        CONTACT_STAGES,
        iter_load_batches,
        simulate_sensors,
    )
    from simulate.generation.run import length_groups

    per = {}
    for _, idx in length_groups(protos):
        group = [protos[i] for i in idx]
        if cfg.protocol.kind in CONTACT_STAGES:
            f = next(iter_load_batches(cfg, group))[1].contact_force_n
        else:
            sens, _ = simulate_sensors(cfg, group)
            f = np.concatenate([sens[..., 4:6], -sens[..., 6:7]], axis=-1)
        per.update({i: f[j] for j, i in enumerate(idx)})
    return np.concatenate([per[i] for i in range(len(protos))])


def study(family: str, n_episodes: int, overrides: list[str], steps_ms: list[float] | None = None) -> dict:
    from scenes import load_scene
    from simulate.generation.run import episode_protocols

    base = load_scene(family, overrides)
    period = 1.0 / base.sampling.sample_rate_hz
    steps = [s / 1e3 for s in CANDIDATES_MS if abs(period / (s / 1e3) - round(period / (s / 1e3))) < 1e-9]
    steps = sorted({round(s, 12) for s in steps} | {round(period / k, 12) for k in PERIOD_DIVISORS
                                                   if period / k >= REFERENCE_S - 1e-12})
    if steps_ms:  # a subset (a check with more episodes): the candidates nearest these
        steps = sorted({min(steps, key=lambda s: abs(s - m / 1e3)) for m in steps_ms})
    protos = episode_protocols(base, list(range(n_episodes)), list(range(n_episodes)))
    t0 = time.perf_counter()
    ref = contact_forces(load_scene(family, overrides + [f"sampling.physics_timestep_s={REFERENCE_S}"]), protos)
    t_ref = time.perf_counter() - t0
    force_ctrl = base.protocol.control == "force"
    full = float(base.protocol.amplitude_max) if force_ctrl else float(np.abs(ref).max())
    rows = []
    for dt in steps:
        cfg = load_scene(family, overrides + [f"sampling.physics_timestep_s={dt!r}"])
        t0 = time.perf_counter()
        f = contact_forces(cfg, protos)
        err = np.abs(f - ref)
        finite = bool(np.isfinite(f).all())
        worst = float(err.max()) if finite else float("inf")
        rows.append({
            "physics_timestep_s": dt,
            "substeps": cfg.sampling.substeps,
            "max_abs_error_n": worst,
            "max_error_of_full_scale": worst / full,
            "normal_max_error_of_full_scale": float(err[:, 2].max()) / full if finite else float("inf"),
            "mean_abs_error_of_full_scale": float(err.mean()) / full if finite else float("inf"),
            "within_tolerance": bool(finite and worst <= TOLERANCE * full),
            "c_mujoco_seconds": time.perf_counter() - t0,
        })
        print(f"{family} dt {dt * 1e3:5.1f} ms: max |dF| {worst:.3e} N = {worst / full:.2e} of full scale")
    ok = [r["physics_timestep_s"] for r in rows if r["within_tolerance"]]
    # the largest step such that it and every smaller candidate pass (a larger one passing by luck is not taken)
    largest = None
    for r in rows:
        if not r["within_tolerance"]:
            break
        largest = r["physics_timestep_s"]
    return {
        "family": family,
        "protocol_kind": base.protocol.kind,
        "control": base.protocol.control,
        "overrides": overrides,
        "episodes": n_episodes,
        "samples_per_episode": sorted({p.n_samples for p in protos}),
        "sample_rate_hz": base.sampling.sample_rate_hz,
        "preset_physics_timestep_s": base.sampling.physics_timestep_s,
        "reference_timestep_s": REFERENCE_S,
        "reference_seconds": t_ref,
        "full_scale_n": full,
        "full_scale_is": "protocol.amplitude_max" if force_ctrl else "max |F| of the reference",
        "tolerance_of_full_scale": TOLERANCE,
        "engine": "C MuJoCo (float64, CPU): the step is the model's; MuJoCo Warp runs the same model",
        "steps": rows,
        "passing_steps_s": ok,
        "largest_step_within_tolerance_s": largest,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--families", default="fabric_1,velostat,ntype,cnt_pdms")
    ap.add_argument("--episodes", type=int, default=8)
    ap.add_argument("--set", action="append", default=[], help="scene override for every family")
    ap.add_argument("--steps-ms", default="", help="only the candidates nearest these steps (comma-separated ms)")
    ap.add_argument("--tag", default="", help="suffix of the results file (physics-step-<family><tag>.json)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    a = ap.parse_args()
    sub = [float(x) for x in a.steps_ms.split(",") if x]
    for fam in a.families.split(","):
        res = {"host": platform.node(), **study(fam, a.episodes, a.set, sub or None)}
        path = a.out / f"physics-step-{fam}{a.tag}.json"
        path.write_text(json.dumps(res, indent=1) + "\n")
        print(f"{fam}: largest step within {TOLERANCE:.1%} of full scale: {res['largest_step_within_tolerance_s']} s -> {path}")


if __name__ == "__main__":
    main()

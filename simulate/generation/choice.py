"""`--physics auto` / `--device auto` / `--workers auto`: which contact engine, device and processes a run uses.

The CLI's defaults are `auto`: on a machine with a CUDA device and the `mujoco_warp` package, a scene whose
protocol has a MuJoCo Warp path steps its worlds on the GPU, its sensor kernels run there, and the GPU feed
writes through several writer processes (`simulate.generation.feed`); elsewhere the C MuJoCo path on the CPU
runs exactly as before (the same config, so the same bytes). A choice the user made (a flag, a scene file or
`--set generation.physics=...`) is kept. `choose` says why it picked what it picked; the CLI prints that line.

The resolved choice goes into the config as concrete values (`generation.physics=mujoco_warp`,
`generation.device=cuda`), so the recordings name the engine that ran, not "auto".
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

from scenes import SceneConfig
from simulate.protocols.compression_tester import KINDS as _VELOSTAT_KINDS

# (protocol kind, control) whose MuJoCo Warp path is checked against C MuJoCo (contact force within 2e-3 of full
# scale, measured <= 3e-5 on Warp's CPU device): the position-controlled box press of cnt_pdms
# (tests/test_contact_mjw.py), the force-controlled staircases of fabric and the compression-tester kinds of
# velostat (tests/test_contact_mjw_force.py; marked gpu for CUDA, slow for Warp's CPU device), and ntype's
# press_stroke, whose contact stage runs its per-step stick-slip in a kernel after every MuJoCo Warp step
# (simulate.contact.mujoco_warp.StickSlipWorlds, tests/test_press_stroke_mjw.py). element_loads has no MuJoCo stage.
GPU_PROTOCOLS = {("sinusoid", "displacement"), ("hold", "displacement"), ("staircase", "force"),
                 *((k, "force") for k in _VELOSTAT_KINDS), ("press_stroke", "force")}
GPU_PROTOCOL_KINDS = tuple(sorted({k for k, _ in GPU_PROTOCOLS}))
GPU_CONTROLS = ("displacement", "force")
# the physics step the GPU path takes where `auto` chose it and the user set none (--set sampling.physics_timestep_s),
# if larger than the scene's: the largest step that divides the sample period and stays within the protocol's limit
# here, the largest candidate whose contact force (and every smaller candidate's) stays within 0.5 % of full scale of
# a 1 ms reference on the family's default protocol (bench/bench_physics_step.py, results/physics-step-<family>.json;
# the step is the model's, so C MuJoCo measured it; the candidates are the round steps and the 10 Hz period / 10-20).
# Keyed by protocol kind: contact_design scales the indenter's armature so that sqrt(k / m) dt is fixed (where the
# armature sets the mass: every preset), so the contact mode's period is a fixed number of steps whatever the pad's
# stiffness, and the error depends on the step against the protocol's ramps, not on the pad. Measured (8 episodes of
# the default protocol; velostat also on 32): velostat_mix 5 ms 2.6e-3 of full scale (32 episodes: 3.5e-3), 100/13 =
# 7.69 ms 4.85e-3 (32: 4.85e-3), 100/12 = 8.33 ms 5.4e-3 (the preset's 2 ms: 5.9e-4); fabric_1 staircase 5 ms (the
# preset's) 3.6e-3, 100/19 = 5.26 ms 4.6e-3, 100/18 = 5.56 ms 5.8e-3. Until session 24 the round candidates only:
# 5 ms for both.
GPU_PHYSICS_STEP_S: dict[str, float] = {"staircase": 0.1 / 19, **{k: 0.1 / 13 for k in _VELOSTAT_KINDS}}
# where the GPU feed runs and the scene names no compression: Blosc2 lz4 (level 1 + shuffle, one thread per writer
# process), for every family: the writers' CPU per episode of each preset's default episodes (this 2-core host,
# bench/results/writer-episode-cpu.json) is lowest with lz4 in every family: cnt_pdms 16.5 ms (lzf 48.4, zstd 18.5),
# fabric_1 3.6 (5.5, 4.6), velostat 8.3 (15.3, 9.8), ntype 2.9 (3.2, 3.3), for 8 % more bytes than lzf
# (cnt_pdms), 21 % (fabric_1), 26 % fewer (velostat), 14 % more (ntype); zstd makes 11-35 % fewer bytes than lz4 for
# 11-29 % more writer CPU (--set generation.compression=zstd). Before session 11 only cnt_pdms took lz4: Blosc2 then
# started its default threads for every chunk (0.8-1.3 ms per chunk here; 252 writer-seconds for cnt_pdms' 4096
# episodes on the H100, user-cli-h100-s10-cnt.json), which the narrow chunks of the other families multiplied.
# The CPU path keeps the scene's lzf (its config, so its content hash, stays as before).
GPU_COMPRESSION = "lz4"
# writer processes of the GPU feed: all cores but 4 (the driver, the physics, the OS), at most 12: on the 16-core
# H100 host 12 writers ran the 4096-episode CLI run in 122 s against 156 s with 8 (user-cli-h100-cnt-w12.json)
MAX_AUTO_WRITERS = 12
RESERVED_CORES = 4


@dataclass(frozen=True)
class Choice:
    physics: str  # "mujoco" | "mujoco_warp"
    physics_device: str  # "cpu" | "cuda:N"
    device: str  # Warp device of the sensor kernels
    workers: int
    reason: str  # why (auto) or "as asked"
    overrides: list[str] = field(default_factory=list)  # config overrides that make the choice concrete

    def line(self) -> str:
        engine = "MuJoCo Warp" if self.physics == "mujoco_warp" else "C MuJoCo"
        feed = (f", GPU feed with {self.workers} writer process(es)" if self.physics == "mujoco_warp" and self.workers > 1
                else f", {self.workers} worker process(es)")
        comp = next((o.split("=", 1)[1] for o in self.overrides if o.startswith("generation.compression=")), None)
        comp = f", {comp} compression" if comp else ""
        step = next((o.split("=", 1)[1] for o in self.overrides if o.startswith("sampling.physics_timestep_s=")), None)
        comp += f", physics step {float(step) * 1e3:.3g} ms (GPU default of the protocol)" if step else ""
        return (f"engine: {engine} on {self.physics_device}, sensor kernels on {self.device}{feed}{comp} "
                f"({self.reason})")


def _cuda() -> tuple[int, str]:
    """(number of CUDA devices Warp sees, name of the first)."""
    from sensors.warp_setup import init_warp

    init_warp()
    import warp as wp

    n = wp.get_cuda_device_count()
    return n, (wp.get_device("cuda:0").name if n else "")


def gpu_blocker(cfg: SceneConfig) -> str | None:
    """Why this scene has no MuJoCo Warp path that `auto` would take (None: it has one)."""
    from simulate.contact.load_field import CONTACT_STAGES

    p = cfg.protocol
    if p.kind in CONTACT_STAGES and (p.kind, p.control) not in GPU_PROTOCOLS:
        return f"protocol '{p.kind}' has its own C MuJoCo contact stage, no MuJoCo Warp path"
    if (p.kind, p.control) not in GPU_PROTOCOLS:
        return f"MuJoCo Warp not validated for protocol '{p.kind}' ({p.control} control); force it with --physics mujoco_warp"
    return None


def gpu_physics_step(cfg: SceneConfig) -> float | None:
    """The GPU path's physics step for this scene: the largest step that divides the sample period and is at most
    the protocol's limit (GPU_PHYSICS_STEP_S), period / ceil(period / limit), where that is larger than the scene's;
    else None (the scene's step stays). At 10 Hz a limit of 100/13 ms gives 100/13 ms, at 20 Hz 50/7 ms."""
    limit = GPU_PHYSICS_STEP_S.get(cfg.protocol.kind)
    if limit is None:
        return None
    period = 1.0 / cfg.sampling.sample_rate_hz
    step = period / math.ceil(period / limit - 1e-9)
    return step if step > cfg.sampling.physics_timestep_s * (1 + 1e-9) else None


def choose(cfg: SceneConfig, physics: str = "auto", device: str = "auto", workers: int | None = None,
           backend: str = "warp", cuda: tuple[int, str] | None = None, mjw: bool | None = None,
           step_asked: bool = False) -> Choice:
    """The engine, devices and processes for generating `cfg`.

    physics, device: the CLI's flags ("auto" = choose); a generation.physics the scene or --set gave (anything
    but "auto") counts as asked. workers: None = choose. cuda, mjw: what this machine has (default: ask Warp,
    try importing mujoco_warp), for tests. step_asked: the user set sampling.physics_timestep_s (--set), so
    `auto` keeps it (otherwise an auto-chosen GPU path takes `gpu_physics_step`).
    """
    from simulate.contact.mujoco_warp import available

    g = cfg.generation
    asked = f"--physics {physics} as asked"
    if physics == "auto" and "physics" in g.model_fields_set and g.physics != "auto":
        physics, asked = g.physics, f"generation.physics={g.physics} as set"  # the scene file or --set chose it
    if device == "auto" and "device" in g.model_fields_set and g.device != "auto":
        device = g.device
    if cuda is None:
        cuda = _cuda() if backend == "warp" or physics != "mujoco" or device != "cpu" else (0, "")
    n_cuda, gpu_name = cuda
    mjw = available() if mjw is None else mjw

    overrides: list[str] = []
    if physics == "auto":
        blocker = gpu_blocker(cfg)
        if n_cuda == 0:
            why = "auto: no CUDA device"
        elif not mjw:
            why = "auto: mujoco_warp not installed (pip install 'piezotwin[gpu]')"
        elif blocker:
            why = f"auto: {blocker}"
        else:
            why = f"auto: CUDA device {gpu_name} and mujoco_warp found"
        physics = "mujoco_warp" if n_cuda and mjw and not blocker else "mujoco"
    else:
        why = asked
    if device == "auto":
        device = "cuda:0" if n_cuda and (backend == "warp" or physics == "mujoco_warp") else "cpu"
    elif device == "cuda":
        device = "cuda:0"
    if physics == "mujoco_warp":
        overrides += ["generation.physics=mujoco_warp", f"generation.device={'cuda' if device.startswith('cuda') else 'cpu'}"]
        physics_device = device
        if physics_device.startswith("cuda") and "compression" not in g.model_fields_set:
            overrides.append(f"generation.compression={GPU_COMPRESSION}")
        step = gpu_physics_step(cfg) if why.startswith("auto") and not step_asked else None
        if step is not None:
            overrides.append(f"sampling.physics_timestep_s={step!r}")
    else:
        physics_device = "cpu"
        if "physics" in g.model_fields_set:
            overrides.append(f"generation.physics={physics}")  # "auto" made concrete
    if workers is None:
        if physics == "mujoco_warp" and physics_device.startswith("cuda") and n_cuda == 1:
            workers = max(2, min(MAX_AUTO_WRITERS, (os.cpu_count() or 2) - RESERVED_CORES))
        elif physics == "mujoco" and device.startswith("cuda") and why.startswith("auto"):
            # C MuJoCo with the sensor kernels on a GPU (fabric, velostat, ntype): shards in worker processes
            # (spawned, each with its own CUDA context). fabric_1 64 episodes on the H100 host: 19.0 s with 8
            # workers against 36.1 s with 1 (user-cli-h100-s6-fabric-w8.json, user-cli-h100.json). A machine
            # without CUDA keeps one process, as before
            workers = max(1, min(MAX_AUTO_WRITERS, (os.cpu_count() or 2) - RESERVED_CORES))
        else:
            workers = 1
    return Choice(physics, physics_device, device, workers, why, overrides)

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

import os
from dataclasses import dataclass, field

from scenes import SceneConfig

# protocol kinds whose MuJoCo Warp path is checked against C MuJoCo (tests/test_contact_mjw.py, marked gpu):
# the position-controlled box press of cnt_pdms. Kinds with their own contact stage (press_stroke) have none;
# force-controlled kinds run on MuJoCo Warp only when asked for (--physics mujoco_warp).
GPU_PROTOCOL_KINDS = ("sinusoid", "hold")
GPU_CONTROLS = ("displacement",)
# where the GPU feed runs and the scene names no compression: Blosc2 lz4 (level 1 + shuffle). The plain CLI on the
# H100 (`generate cnt_pdms --episodes 4096`, 8 writers) ran 117 s with lz4 against 156 s with zstd for 14 % more
# bytes (bench/results/user-cli-h100-cnt-lz4.json vs user-cli-h100-cnt.json): the writers' compression was the
# bound. The CPU path keeps lzf (the same bytes as before)
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
    if p.kind in CONTACT_STAGES:
        return f"protocol '{p.kind}' has its own C MuJoCo contact stage, no MuJoCo Warp path"
    if p.kind not in GPU_PROTOCOL_KINDS or p.control not in GPU_CONTROLS:
        return f"MuJoCo Warp not validated for protocol '{p.kind}' ({p.control} control); force it with --physics mujoco_warp"
    return None


def choose(cfg: SceneConfig, physics: str = "auto", device: str = "auto", workers: int | None = None,
           backend: str = "warp", cuda: tuple[int, str] | None = None, mjw: bool | None = None) -> Choice:
    """The engine, devices and processes for generating `cfg`.

    physics, device: the CLI's flags ("auto" = choose); a generation.physics the scene or --set gave (anything
    but "auto") counts as asked. workers: None = choose. cuda, mjw: what this machine has (default: ask Warp,
    try importing mujoco_warp), for tests.
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

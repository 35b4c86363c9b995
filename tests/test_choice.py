"""`--physics auto` / `--device auto` / `--workers auto` (simulate/generation/choice.py): what runs where, and why."""

import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from scenes import load_scene
from simulate.generation import choice
from simulate.generation.choice import choose

H100 = (1, "NVIDIA H100 80GB HBM3")


def test_cpu_machine_keeps_the_c_engine_and_says_why():
    c = choose(load_scene("cnt_pdms"), cuda=(0, ""), mjw=True)
    assert (c.physics, c.physics_device, c.device, c.workers) == ("mujoco", "cpu", "cpu", 1)
    assert c.overrides == []  # the config stays as it was: same bytes as before auto
    assert "C MuJoCo on cpu" in c.line() and "auto: no CUDA device" in c.line()
    c = choose(load_scene("cnt_pdms"), cuda=H100, mjw=False)
    assert c.physics == "mujoco" and "mujoco_warp not installed" in c.reason
    assert c.device == "cuda:0"  # the sensor kernels still take the GPU


def test_gpu_machine_takes_the_gpu_feed():
    c = choose(load_scene("cnt_pdms"), cuda=H100, mjw=True)
    assert (c.physics, c.physics_device, c.device) == ("mujoco_warp", "cuda:0", "cuda:0")
    assert c.workers >= 2  # writer processes of the feed
    assert c.overrides == ["generation.physics=mujoco_warp", "generation.device=cuda", "generation.compression=lz4"]
    assert "lz4 compression" in c.line()
    c2 = choose(load_scene("cnt_pdms", ["generation.compression=none"]), cuda=H100, mjw=True)
    assert not any("compression" in o for o in c2.overrides)  # the scene's own choice stays
    assert "MuJoCo Warp on cuda:0" in c.line() and "NVIDIA H100" in c.line() and "GPU feed" in c.line()
    cfg = load_scene("cnt_pdms", c.overrides)  # the recordings name the engine that ran, not "auto"
    assert cfg.generation.physics == "mujoco_warp" and cfg.generation.device == "cuda" and cfg.generation.compression == "lz4"


def test_user_choice_wins():
    c = choose(load_scene("cnt_pdms"), physics="mujoco", cuda=H100, mjw=True)
    assert c.physics == "mujoco" and "--physics mujoco as asked" in c.reason and c.workers == 1
    c = choose(load_scene("cnt_pdms", ["generation.physics=mujoco"]), cuda=H100, mjw=True)
    assert c.physics == "mujoco" and "generation.physics=mujoco as set" in c.reason
    c = choose(load_scene("cnt_pdms"), physics="mujoco_warp", device="cpu", cuda=H100, mjw=True)
    assert (c.physics, c.physics_device) == ("mujoco_warp", "cpu")  # Warp's CPU device, as asked
    c = choose(load_scene("cnt_pdms"), workers=3, cuda=H100, mjw=True)
    assert c.workers == 3
    c = choose(load_scene("cnt_pdms", ["generation.physics=auto"]), cuda=(0, ""), mjw=True)
    assert c.overrides == ["generation.physics=mujoco"]  # "auto" in a scene file made concrete


@pytest.mark.parametrize("preset, extra, needle", [("ntype", ["protocol.kind=element_loads"], "element_loads"),
                                                   ("fabric_1", ["protocol.kind=sinusoid"], "'sinusoid' (force control)")])
def test_scenes_without_a_validated_gpu_path_stay_on_c_mujoco(preset, extra, needle):
    c = choose(load_scene(preset, extra), cuda=H100, mjw=True)
    assert c.physics == "mujoco" and needle in c.reason


@pytest.mark.parametrize("preset", ["fabric_1", "fabric_6", "velostat", "ntype"])
def test_force_controlled_presets_take_the_gpu_with_their_physics_step(preset, monkeypatch):
    """fabric staircases, velostat kinds and ntype's press_stroke have a checked MuJoCo Warp path
    (tests/test_contact_mjw_force.py, tests/test_press_stroke_mjw.py);
    auto takes it, with the protocol's GPU step where it is larger than the scene's, unless the user set one."""
    cfg = load_scene(preset)
    monkeypatch.setitem(choice.GPU_PHYSICS_STEP_S, cfg.protocol.kind, 0.01)
    c = choose(cfg, cuda=H100, mjw=True)
    assert c.physics == "mujoco_warp" and c.overrides[-1] == "sampling.physics_timestep_s=0.01"
    assert "generation.compression=lz4" in c.overrides  # every family's writers are fastest with lz4 (writer-episode-cpu.json)
    assert "physics step 10 ms" in c.line()
    assert load_scene(preset, c.overrides).sampling.substeps == 10  # 10 Hz samples, every preset here
    assert choose(cfg, cuda=H100, mjw=True, step_asked=True).overrides[-1] != "sampling.physics_timestep_s=0.01"
    assert not any("physics_timestep" in o for o in choose(cfg, physics="mujoco_warp", cuda=H100, mjw=True).overrides)
    # a limit that does not divide the sample period: the largest step below it that does (0.1 s / 34)
    # (where that is still larger than the scene's own step: fabric's presets step at 5 ms)
    monkeypatch.setitem(choice.GPU_PHYSICS_STEP_S, cfg.protocol.kind, 0.003)
    below = choice.gpu_physics_step(cfg)
    assert below == (pytest.approx(0.1 / 34, rel=1e-12) if cfg.sampling.physics_timestep_s < 0.1 / 34 else None)
    assert load_scene(preset, [f"sampling.physics_timestep_s={0.1 / 34!r}"]).sampling.substeps == 34
    monkeypatch.setitem(choice.GPU_PHYSICS_STEP_S, cfg.protocol.kind, 0.1 / 13)  # at 20 Hz: 50 / 7 ms, at 10 Hz 100 / 13
    assert choice.gpu_physics_step(load_scene(preset, ["sampling.sample_rate_hz=20"])) == pytest.approx(0.05 / 7, rel=1e-12)
    assert choice.gpu_physics_step(cfg) == pytest.approx(0.1 / 13, rel=1e-12)
    assert "physics step 7.69 ms" in choose(cfg, cuda=H100, mjw=True).line()
    monkeypatch.setitem(choice.GPU_PHYSICS_STEP_S, cfg.protocol.kind, 0.001)  # smaller than the scene's: kept
    assert choice.gpu_physics_step(cfg) is None


def test_cli_default_is_auto_and_same_bytes_as_the_c_engine(tmp_path, monkeypatch):
    monkeypatch.setattr(choice, "_cuda", lambda: (0, ""))  # a machine without CUDA, whatever runs the test
    fast = ["--episodes", "2", "--set", "protocol.frequencies_hz=[2.0]", "--set", "protocol.cycles=1",
            "--set", "pad.taxels_x=4", "--set", "pad.taxels_y=4", "--set", "generation.episodes_per_shard=2"]
    runner = CliRunner()
    res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(tmp_path / "auto")] + fast)
    assert res.exit_code == 0, res.output
    assert "engine: C MuJoCo on cpu, sensor kernels on cpu" in res.output and "(auto: no CUDA device)" in res.output
    res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(tmp_path / "forced"), "--physics", "mujoco", "--device", "cpu"] + fast)
    assert res.exit_code == 0, res.output
    assert "--physics mujoco as asked" in res.output
    a, b = (tmp_path / d / "shard-00000.h5" for d in ("auto", "forced"))
    assert _contents(a) == _contents(b)  # every dataset and attribute but the creation time


def _contents(path) -> dict:
    import h5py
    import numpy as np

    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            for k, v in obj.attrs.items():
                if k != "created_utc":
                    out[f"{name}@{k}"] = repr(v)
            if isinstance(obj, h5py.Dataset):
                out[name] = np.asarray(obj[()]).tobytes()
        visit("/", f)
        f.visititems(visit)
    return out


def test_cpu_physics_with_gpu_sensors_takes_worker_processes(monkeypatch):
    """C MuJoCo with the sensor kernels on a GPU (auto): shards in all cores but 4 (at most 12) worker processes;
    the same scene on a machine without CUDA keeps one process (the CPU path as before)."""
    import simulate.generation.choice as ch

    monkeypatch.setattr(ch.os, "cpu_count", lambda: 16)
    c = choose(load_scene("ntype", ["protocol.kind=element_loads"]), cuda=H100, mjw=True)
    assert (c.physics, c.device, c.workers) == ("mujoco", "cuda:0", 12)
    assert "12 worker process(es)" in c.line()
    monkeypatch.setattr(ch.os, "cpu_count", lambda: 2)
    assert choose(load_scene("ntype", ["protocol.kind=element_loads"]), cuda=H100, mjw=True).workers == 1
    assert choose(load_scene("ntype", ["protocol.kind=element_loads"]), cuda=(0, ""), mjw=True).workers == 1


@pytest.mark.parametrize("preset, primitive", [("cnt_pdms", False), ("fabric_1", True), ("velostat", True),
                                               ("ntype", True)])
def test_box_box_primitive_only_where_contacts_are_micrometres_deep(preset, primitive):
    """Force-controlled presets hold contacts of a few um, which MuJoCo Warp's convex collider misses; the
    displacement-controlled cnt_pdms press is mm deep and steps faster with the convex collider."""
    from simulate.contact.mujoco_warp import box_primitive_for

    assert box_primitive_for(load_scene(preset).protocol.control) is primitive

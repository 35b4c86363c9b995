"""The MuJoCo Warp contact stage against the C MuJoCo rollout, and the engine choice.

The equivalence runs on Warp's CPU device (slow: ~75 s of kernel compilation when the cache is cold,
marked slow) and on CUDA (marked gpu, run on the device machine: pytest -m gpu)."""

import numpy as np
import pytest

from scenes import load_scene
from simulate.contact.load_field import physics_engine, simulate_sensors
from simulate.contact.mujoco_warp import available
from simulate.protocols.indenter import make_episode_protocol

needs_mjw = pytest.mark.skipif(not available(), reason="mujoco_warp not installed (extra: gpu)")
SHORT = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=6", "pad.taxels_y=6"]


def _compare(device: str, n_episodes: int) -> None:
    dev = "cpu" if device == "cpu" else "cuda"
    cfg = load_scene("cnt_pdms", SHORT)
    cfg_w = load_scene("cnt_pdms", SHORT + ["generation.physics=mujoco_warp", f"generation.device={dev}"])
    protos = [make_episode_protocol(cfg, s) for s in range(n_episodes)]
    a, ta = simulate_sensors(cfg, protos)
    b, tb = simulate_sensors(cfg_w, protos)
    np.testing.assert_array_equal(ta, tb)
    fa, fb = a[..., 4:7], b[..., 4:7]
    fmax = np.abs(fa).max()
    assert fmax > 1.0  # the episodes press: a loaded contact is compared, not two zeros
    # float32 worlds vs float64 C MuJoCo, same model and controls: forces within 0.2 % of full scale
    # (measured 6e-4 of full scale on Warp's CPU device, at contact onset), positions within 0.1 um
    assert np.abs(fa - fb).max() < 2e-3 * fmax
    np.testing.assert_allclose(b[..., 0:3], a[..., 0:3], atol=1e-7)
    # where the pad carries load, both engines see the contact
    loaded = fa[..., 2] < -0.01 * fmax
    assert (b[..., 3][loaded] > 0).all()


@needs_mjw
@pytest.mark.slow
def test_mjw_cpu_matches_c_mujoco():
    _compare("cpu", 3)


@needs_mjw
@pytest.mark.gpu
def test_mjw_cuda_matches_c_mujoco(gpu_device):
    _compare(gpu_device, 64)


def test_physics_engine_choice():
    cfg = load_scene("cnt_pdms")
    assert physics_engine(cfg) == ("mujoco", "cpu")  # the default stays the C engine
    auto = load_scene("cnt_pdms", ["generation.physics=auto"])
    from sensors.warp_setup import resolve_device

    expect_gpu = resolve_device("auto") != "cpu" and available()
    assert physics_engine(auto)[0] == ("mujoco_warp" if expect_gpu else "mujoco")


def test_record_subset_and_errors(tmp_path):
    from sensors.data.recording import Recording
    from simulate.generation.run import check_record, generate

    keep = ["time", "adc", "force_taxel", "contact_force"]
    cfg = load_scene("cnt_pdms", SHORT + ["generation.episodes=2", "generation.episodes_per_shard=2",
                                          "sensor.readout=taxel", f"generation.record=[{','.join(keep)}]"])
    generate(cfg, tmp_path / "ds")
    from sensors.data.manifest import shard_path

    with Recording(shard_path(tmp_path / "ds", 0)) as rec:
        assert rec.attrs["physics_engine"] == "mujoco"  # the engine that ran is recorded in every shard
        ep = rec.episode_ids[0]
        assert sorted(rec.channels(ep)) == sorted(keep)
        assert rec.shape(ep, "adc")[-1] == 36  # one ADC channel per taxel
    bad = load_scene("cnt_pdms", ["generation.record=[adc, forse]"])
    with pytest.raises(ValueError, match=r"forse.*allowed: .*force_taxel"):
        check_record(bad)


def test_taxel_readout_localises_the_press():
    """sensor.readout = taxel: the pressed taxel's channel falls in resistance, a far one stays at rest."""
    from sensors.cnt_pdms.model import CntPdmsSensor

    cfg = load_scene("cnt_pdms", ["pad.taxels_x=6", "pad.taxels_y=6", "sensor.readout=taxel"])
    s = CntPdmsSensor(cfg, backend="numpy")
    T, N = 300, 36
    drive = np.zeros((1, T, N), np.float32)
    drive[0, 50:, 14] = 0.02  # strain under taxel 14 only
    out = s.run(drive, [0])
    r = out["resistance"][0]
    assert r.shape == (T, N)
    assert r[-1, 14] < 0.9 * r[0, 14]
    np.testing.assert_allclose(r[-1, 0], r[0, 0], rtol=1e-6)
    # one taxel alone is N times the whole pad's rest resistance
    pad = CntPdmsSensor(load_scene("cnt_pdms", ["pad.taxels_x=6", "pad.taxels_y=6"]), backend="numpy")
    r_pad = pad.run(np.zeros((1, 5, N), np.float32), [0])["resistance"][0, 0, 0]
    np.testing.assert_allclose(r[0, 0], N * r_pad, rtol=1e-5)


@pytest.mark.parametrize("shape", ["box", "sphere"])
def test_load_field_warp_equals_numpy(shape):
    """The Warp load field (GPU path) against its numpy reference, incl. the no-overlap fallback frames."""
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field import load_field
    from simulate.contact.load_field_kernels import load_field_warp

    init_warp()
    extra = ["pad.taxels_x=5", "pad.taxels_y=4"] + (["indenter.shape=sphere", "indenter.radius_m=6 mm"] if shape == "sphere" else [])
    cfg = load_scene("cnt_pdms", extra)
    rng = np.random.default_rng(3)
    E, T = 3, 40
    pos = np.stack([rng.uniform(-0.02, 0.02, (E, T)), rng.uniform(-0.02, 0.02, (E, T)), rng.uniform(-2e-4, 1e-4, (E, T))], -1)
    force = np.stack([rng.normal(0, 0.3, (E, T)), rng.normal(0, 0.3, (E, T)), rng.uniform(-1, 5, (E, T))], -1)
    pos[0, :5, :2] = 0.024  # just off the pad while loaded: the centre-Gaussian fallback
    force[0, :5, 2] = 2.0
    a = load_field(cfg, pos, force)
    b = load_field_warp(cfg, pos, force, "cpu")
    for x, y, name in zip(a, b, ("deformation", "pressure", "shear")):
        np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-12 * float(np.abs(x).max()), err_msg=name)
    assert (a[1][0, :5].sum(-1) > 0).all()  # the fallback frames did carry load


def test_taxel_readout_gain_keeps_a_full_press_inside_the_adc_range():
    """A taxel readout gets its own default gain (the pad's would clip); an explicit gain is kept."""
    from sensors.cnt_pdms.model import CntPdmsSensor

    cfg = load_scene("cnt_pdms", ["pad.taxels_x=6", "pad.taxels_y=6", "sensor.readout=taxel"])
    assert load_scene("cnt_pdms", ["sensor.readout=taxel", "sensor.electronics.amp_gain=100"]).sensor.electronics.amp_gain == 100
    drive = np.zeros((1, 400, 36), np.float32)
    drive[0, 100:, 14] = 160e-6 / cfg.pad.thickness_m  # the preset's full-scale press, under one taxel
    adc = CntPdmsSensor(cfg, backend="numpy").run(drive, [0])["adc"][0, :, 14].astype(int)
    full = 2 ** (cfg.sensor.electronics.adc_bits - 1)
    assert 0.5 * full < np.abs(adc[-50:]).max() < 0.95 * full  # well resolved, not clipped


@needs_mjw
@pytest.mark.gpu
def test_gpu_generation_keeps_fields_on_device_and_slices_the_sensor_stage(gpu_device, monkeypatch):
    """The GPU path (taxel fields left on the device for cnt_pdms, sensor stage in slices after one physics
    batch) records the same channels as the same worlds with the fields copied to the host in one pass."""
    from sensors.registry import make_sensor
    from simulate.contact import (
        load_field as contact,  # where iter_load_batches looks simulate_sensors up
    )
    from simulate.generation import run

    dev = "cpu" if gpu_device == "cpu" else "cuda"
    rec = "generation.record=[target,position,contact_force,force_taxel,adc]"
    cfg = load_scene("cnt_pdms", SHORT + ["sensor.readout=taxel", "generation.physics=mujoco_warp", f"generation.device={dev}", rec])
    sensor = make_sensor(cfg, "warp", physics_engine(cfg)[1])
    seeds, ids = list(range(10, 17)), [f"ep-{k}" for k in range(7)]
    physics, real = [], contact.simulate_sensors  # one physics run for both (GPU atomics need not repeat bit for bit)
    monkeypatch.setattr(contact, "simulate_sensors", lambda *a: physics[0] if physics else physics.append(real(*a)) or physics[0])
    monkeypatch.setattr(run, "SENSOR_SLICE", 3)
    sliced = run.simulate_episodes(cfg, seeds, ids, sensor)
    monkeypatch.setattr(run, "SENSOR_SLICE", 1000)
    monkeypatch.setattr(type(sensor), "device_load", False)
    whole = run.simulate_episodes(cfg, seeds, ids, sensor)
    assert max(float(np.abs(r.channels["force_taxel"].data).max()) for r in whole) > 0.1  # they press
    for a, b in zip(sliced, whole):
        assert a.channels.keys() == b.channels.keys()
        for k in a.channels:
            np.testing.assert_array_equal(a.channels[k].data, b.channels[k].data, err_msg=f"{a.ep_id} {k}")


def _worlds_runs(device: str):
    """Sensordata of the same episodes: sensors in every step; sensors only in the recorded step, run twice
    on the same (reused) worlds; plus a run of other episodes in between."""
    from simulate.contact.load_field import (
        _initial_states,
        build_model,
        episode_controls,
    )
    from simulate.contact.mujoco_warp import WarpWorlds

    cfg = load_scene("cnt_pdms", SHORT)
    m, sub = build_model(cfg), cfg.sampling.substeps
    protos = [make_episode_protocol(cfg, s) for s in range(4)]
    n = 40  # the press starts within the first 0.4 s
    nstep = (n - 1) * sub
    ctrl, _ = episode_controls(cfg, protos, nstep)
    st, s0 = _initial_states(m, cfg, protos, ctrl[:, 0])
    q0 = st[:, 1 : 1 + m.nq]
    every = WarpWorlds(m, 4, device, sensors_every_step=True).run(q0, ctrl, s0, sub, n)
    ww = WarpWorlds(m, 4, device)
    first = ww.run(q0, ctrl, s0, sub, n)
    ww.run(q0[::-1].copy(), ctrl[::-1].copy(), s0[::-1].copy(), sub, n)  # other states between the two
    again = ww.run(q0, ctrl, s0, sub, n)
    assert np.abs(every[..., 4:7]).max() > 0.5  # a loaded contact is compared
    return every, first, again


@needs_mjw
@pytest.mark.slow
def test_sensors_only_in_the_recorded_step_and_reused_worlds_cpu():
    """Warp's CPU device is deterministic: skipping sensors in the unrecorded substeps, and reusing the worlds
    (buffers, reset) for another batch, change no recorded value."""
    from sensors.warp_setup import init_warp

    init_warp()
    every, first, again = _worlds_runs("cpu")
    np.testing.assert_array_equal(first, every)
    np.testing.assert_array_equal(again, first)


@needs_mjw
@pytest.mark.gpu
def test_sensors_only_in_the_recorded_step_and_reused_worlds_cuda(gpu_device):
    """On CUDA the contact solver sums with atomics: equal within float32 noise (forces within 1e-4 of full scale)."""
    every, first, again = _worlds_runs(gpu_device)
    scale = np.abs(every[..., 4:7]).max()
    for b in (first, again):
        assert np.abs(b[..., 4:7] - every[..., 4:7]).max() < 1e-4 * scale
        np.testing.assert_allclose(b[..., 0:3], every[..., 0:3], atol=1e-8)


@needs_mjw
@pytest.mark.slow
def test_worlds_are_reused_per_shape_until_released():
    """`worlds_for` keeps one set of worlds per process for the next batch of the same scene and size; the GPU feed's
    driver frees them with `release_worlds` once it has stepped its last batch (not at the process's exit)."""
    from simulate.contact.load_field import build_model
    from simulate.contact.mjcf import build_mjcf
    from simulate.contact.mujoco_warp import release_worlds, worlds_for

    cfg = load_scene("cnt_pdms", SHORT)
    m, mjcf = build_model(cfg), build_mjcf(cfg)
    first = worlds_for(m, mjcf, 3, "cpu")
    assert worlds_for(m, mjcf, 3, "cpu") is first
    other = worlds_for(m, mjcf, 2, "cpu")  # another size replaces them
    assert other is not first and worlds_for(m, mjcf, 2, "cpu") is other
    release_worlds()
    assert worlds_for(m, mjcf, 2, "cpu") is not other
    release_worlds()


def _chunked_runs(device: str, monkeypatch) -> tuple[np.ndarray, dict]:
    """Sensordata of the same episodes in one time chunk, and in 5 chunks (the last one short) through 1 and 2
    sets of chunk buffers (`WarpWorlds.run`), on worlds reused between the runs."""
    import simulate.contact.mujoco_warp as mw
    from simulate.contact.load_field import _initial_states, build_model, episode_controls

    cfg = load_scene("cnt_pdms", SHORT)
    m, sub = build_model(cfg), cfg.sampling.substeps
    protos = [make_episode_protocol(cfg, s) for s in range(3)]
    n = 41  # the press starts within the first 0.4 s
    ctrl, _ = episode_controls(cfg, protos, (n - 1) * sub)
    st, s0 = _initial_states(m, cfg, protos, ctrl[:, 0])
    q0 = st[:, 1 : 1 + m.nq]
    ww = mw.WarpWorlds(m, 3, device)
    one = ww.run(q0, ctrl, s0, sub, n)
    per_sample = 3 * (sub * m.nu + ww.n_recorded) * 4
    monkeypatch.setattr(mw, "CHUNK_BYTES", 9 * per_sample)  # chunks of 9 samples: 9, 9, 9, 9, 4
    chunked = {}
    for sets in (1, 2):
        monkeypatch.setattr(mw, "PIPELINE_SETS", sets)
        chunked[sets] = ww.run(q0, lambda sl, eps: ctrl[eps, sl], s0, sub, n)  # controls as a function too
    assert ww._buffers[0] == 9 and len(ww._buffers[2]) == 2  # noqa: SLF001 - the chunking under test did happen
    assert np.abs(one[..., 4:7]).max() > 0.5  # a loaded contact is compared
    return one, chunked


@needs_mjw
@pytest.mark.slow
def test_time_chunks_in_flight_change_no_value_cpu(monkeypatch):
    """Warp's CPU device is deterministic: the time chunks and the sets of chunk buffers they rotate through
    (the controls made straight into them, a short last chunk) give the one-chunk run's values bit for bit."""
    from sensors.warp_setup import init_warp

    init_warp()
    one, chunked = _chunked_runs("cpu", monkeypatch)
    for sets, got in chunked.items():
        np.testing.assert_array_equal(got, one, err_msg=f"{sets} set(s)")


@needs_mjw
@pytest.mark.gpu
def test_time_chunks_in_flight_change_no_value_cuda(gpu_device, monkeypatch):
    """On CUDA the chunks' transfers are asynchronous (two chunks in flight): the one-chunk run's values within
    float32 atomics noise (forces within 1e-4 of full scale, positions within 1e-8 m); a chunk whose controls
    or sensors were taken before they landed would be off by whole samples."""
    one, chunked = _chunked_runs(gpu_device, monkeypatch)
    scale = np.abs(one[..., 4:7]).max()
    for sets, got in chunked.items():
        assert np.abs(got[..., 4:7] - one[..., 4:7]).max() < 1e-4 * scale, f"{sets} set(s)"
        np.testing.assert_allclose(got[..., 0:3], one[..., 0:3], atol=1e-8, err_msg=f"{sets} set(s)")

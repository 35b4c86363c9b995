"""simulate.contact.mjcf and simulate.protocols.indenter: the MJCF compiles, the contact stiffness is the Winkler one,
protocols are seeded draws, waveforms have the paper's shape."""

import mujoco
import numpy as np
import pytest

from scenes import load_scene
from simulate.contact.mjcf import build_mjcf, contact_design
from simulate.protocols.indenter import make_episode_protocol, target_waveform

FAST = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1"]


@pytest.mark.parametrize(
    "overrides",
    [[], ["indenter.shape=sphere"], ["protocol.control=force", "protocol.amplitude_max=5.0"]],
)
def test_mjcf_compiles_with_sensors_and_actuators(overrides):
    cfg = load_scene("cnt_pdms", overrides)
    m = mujoco.MjModel.from_xml_string(build_mjcf(cfg))
    assert m.nq == 3 and m.nu == 3
    assert m.nsensordata == 3 + 17  # jointpos x3 + contact netforce (found, force, torque, dist, pos, normal, tangent)
    assert m.opt.timestep == cfg.sampling.physics_timestep_s
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    pad = m.geom("pad")
    assert pad.pos[2] - pad.size[2] == pytest.approx(0.0)
    assert pad.pos[2] + pad.size[2] == pytest.approx(cfg.pad.thickness_m)


@pytest.mark.parametrize("control", ["displacement", "force"])
def test_static_contact_stiffness_is_winkler(control):
    """Pressed to 100 um, MuJoCo's contact force / penetration equals E A / t within 1 %."""
    cfg = load_scene("cnt_pdms", [f"protocol.control={control}", "protocol.amplitude_max=5.0"] if control == "force" else [])
    k_expected = cfg.pad.youngs_modulus_pa * cfg.indenter.size_x_m * cfg.indenter.size_y_m / cfg.pad.thickness_m
    m = mujoco.MjModel.from_xml_string(build_mjcf(cfg))
    d = mujoco.MjData(m)
    d.ctrl[2] = -1e-4 if control == "displacement" else -k_expected * 1e-4
    for _ in range(3000):
        mujoco.mj_step(m, d)
    pen = -d.qpos[2]
    f_n = -d.sensor("press_net").data[3]  # force on the pad, world z
    assert d.sensor("press_net").data[0] == contact_design(cfg).contact_points
    assert pen > 0.5e-4
    assert f_n / pen == pytest.approx(k_expected, rel=0.01)


def test_protocol_draw_is_seeded_and_in_range():
    cfg = load_scene("cnt_pdms")
    a, b = make_episode_protocol(cfg, 7), make_episode_protocol(cfg, 7)
    assert a.frequency_hz == b.frequency_hz and a.amplitude == b.amplitude
    np.testing.assert_array_equal(a.offset_xy_m, b.offset_xy_m)
    draws = [make_episode_protocol(cfg, s) for s in range(200)]
    assert {p.frequency_hz for p in draws} == set(cfg.protocol.frequencies_hz)
    amps = np.array([p.amplitude for p in draws])
    assert amps.min() >= cfg.protocol.amplitude_min and amps.max() <= cfg.protocol.amplitude_max
    offs = np.array([p.offset_xy_m for p in draws])
    assert np.abs(offs).max() <= cfg.indenter.position_jitter_m and offs.std() > 0.3 * cfg.indenter.position_jitter_m
    for p in draws[:10]:
        assert p.n_samples == round((cfg.protocol.settle_s + cfg.protocol.cycles / p.frequency_hz) * 100.0)


def test_sinusoid_waveform_shape():
    cfg = load_scene("cnt_pdms", FAST)
    p = make_episode_protocol(cfg, 0)
    f, s, d0 = p.frequency_hz, cfg.protocol.settle_s, p.amplitude
    t = np.array([0.0, s * 0.5, s, s + 0.25 / f, s + 0.5 / f, s + 1.0 / f, s + 1.0 / f + 0.1])
    w = target_waveform(p, cfg, t)
    np.testing.assert_allclose(w, [0, 0, 0, d0 / 2, d0, 0, 0], atol=1e-12 * d0 + 1e-18)


def test_hold_waveform_ramps_and_holds():
    cfg = load_scene("cnt_pdms", ["protocol.kind=hold", "protocol.ramp_s=0.5"])
    p = make_episode_protocol(cfg, 1)
    s = cfg.protocol.settle_s
    t = np.linspace(0, s + 3.0, 1000)
    w = target_waveform(p, cfg, t)
    assert np.all(np.diff(w) >= -1e-15)
    assert w[t < s].max() == 0.0
    np.testing.assert_allclose(w[t >= s + 0.5], p.amplitude)
    assert target_waveform(p, cfg, np.array([s + 0.25]))[0] == pytest.approx(p.amplitude / 2)

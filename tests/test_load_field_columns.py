"""simulate.contact.load_field.read_columns: the physics keeps only the sensordata values the load field reads
(each indenter's jointpos, contact found and force), and the load field made from them is the one made from all of
the sensordata, bit for bit."""

import mujoco
import numpy as np

from scenes import load_scene
from simulate.contact import load_field as lf
from simulate.contact.mjcf import SENSORS_PER_INDENTER
from simulate.protocols.indenter import make_episode_protocol

SHORT = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=4", "pad.taxels_y=3"]


def test_read_columns_are_each_indenters_pose_found_and_force():
    cfg = load_scene("cnt_pdms", SHORT + ["indenter.count=2"])
    m = lf.build_model(cfg)
    cols = lf.read_columns(m)
    assert m.nsensordata == 2 * SENSORS_PER_INDENTER
    assert cols == tuple(range(7)) + tuple(range(SENSORS_PER_INDENTER, SENSORS_PER_INDENTER + 7))
    names = [m.sensor(i).name for i in range(m.nsensor)]
    assert names[:4] == ["pos_x", "pos_y", "pos_z", "press_net"]  # jointpos x3, then the contact sensor (found, force, ...)


def test_load_batch_from_the_kept_columns_equals_the_one_from_all():
    cfg = load_scene("cnt_pdms", SHORT)
    protos = [make_episode_protocol(cfg, s) for s in range(3)]
    sens, target = lf.simulate_sensors(cfg, protos)
    m = lf.build_model(cfg)
    assert sens.shape == (3, protos[0].n_samples, len(lf.read_columns(m)))
    # the whole sensordata of the same rollout, made here, and its kept columns
    n, sub = protos[0].n_samples, cfg.sampling.substeps
    nstep = (n - 1) * sub
    ctrl, _ = lf.episode_controls(cfg, protos, nstep)
    states0, sens0 = lf._initial_states(m, cfg, protos, ctrl[:, 0])
    _, sd = mujoco.rollout.rollout(m, mujoco.MjData(m), states0, ctrl, nstep=nstep)
    full = np.concatenate([sens0[:, None], sd[:, np.arange(1, n) * sub - 1]], axis=1)
    assert full.shape[-1] == m.nsensordata > sens.shape[-1]
    np.testing.assert_array_equal(full[..., list(lf.read_columns(m))], sens)
    a, b = lf.load_batch(cfg, full, target), lf.load_batch(cfg, sens, target)
    for name in ("indenter_pos_m", "contact_force_n", "contact_points", "deformation_m", "pressure_pa", "shear_pa"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
    assert float(np.abs(b.pressure_pa).max()) > 0  # the episodes press


def test_tangential_solver_residual_reads_zero():
    """A lateral contact force below TANGENTIAL_RESIDUAL_N + TANGENTIAL_RESIDUAL_SHARE x the normal one (MuJoCo
    Warp's float32 residual on a normal press: <= 2.6e-4 N) reads 0 in the force and so in the shear field; a real
    tangential load (a stroke: tens of % of the normal force, or a small one above the floor) keeps its value, and
    the normal force is untouched."""
    from simulate.contact import load_field as lf

    cfg = load_scene("velostat", ["generation.physics=mujoco"])
    E, T = 4, 3
    sens = np.zeros((E, T, 7))
    sens[..., lf._POS] = [0.0, 0.0, -1e-6]  # the tip 1 um into the pad
    sens[..., lf._FOUND] = 4
    normal = 5.0
    sens[..., lf._FORCE.start + 2] = -normal  # compressive
    floor = lf.TANGENTIAL_RESIDUAL_N + lf.TANGENTIAL_RESIDUAL_SHARE * normal
    lateral = {0: 2.6e-4, 1: 0.9 * floor, 2: 1.5 * floor, 3: 0.2 * normal}  # episode -> lateral force (N)
    for e, t in lateral.items():
        sens[e, :, lf._FORCE.start] = 0.6 * t
        sens[e, :, lf._FORCE.start + 1] = -0.8 * t
    sens[3, 1, lf._FORCE] = [5e-3, 0.0, 0.0]  # no normal force, a lateral one above the floor: kept
    sens[3, 2, lf._FORCE] = [1e-4, 0.0, 0.0]  # no normal force, a residual: 0
    b = lf.load_batch(cfg, sens, np.zeros((E, T)))
    f = b.contact_force_n
    assert (f[:2, :, :2] == 0).all() and (b.shear_pa[:2] == 0).all()  # residual: no force, no shear
    np.testing.assert_allclose(f[2, :, :2], [[0.6 * 1.5 * floor, -0.8 * 1.5 * floor]] * T, rtol=1e-6)
    np.testing.assert_allclose(f[3, 0, :2], [0.6 * 0.2 * normal, -0.8 * 0.2 * normal], rtol=1e-6)
    assert f[3, 1, 0] == 5e-3 and f[3, 2, 0] == 0 and np.abs(b.shear_pa[2:]).max() > 0
    assert (f[..., 2][f[..., 2] != 0] == normal).all()  # the normal force is untouched

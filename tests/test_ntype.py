"""ntype (N-type 6 x 6 3-D force array): column signs and magnitudes, the paper's resistance ranges,
crosstalk falling with distance, stick-slip shear from MuJoCo strokes, Warp == numpy, config errors."""

import numpy as np
import pytest

from scenes import ConfigError, load_scene
from sensors.ntype.model import NtypeSensor
from simulate.characterize.ntype import patch_load, pure_and_crosstalk

RX, RY, RZ = 0, 1, 2


@pytest.fixture(scope="module")
def cfg():
    return load_scene("ntype")


@pytest.fixture(scope="module")
def pc(cfg):
    return pure_and_crosstalk(cfg, backend="numpy")


def test_columns_signs_and_magnitudes_under_pure_loads(pc):
    fz, fx, mfx, fy = (np.array(pc["pure"][k]["rel_pct"]) for k in ("Fz", "Fx", "-Fx", "Fy"))
    # F_z: every column shortens, the normal column by far the most
    assert np.all(fz < 0) and fz[RZ] < 5 * fz[RX]
    # F_x: the inclined columns answer with opposite signs, the normal column not at all; -F_x mirrors it
    assert fx[RX] > 5 and fx[RY] < -5 and abs(fx[RZ]) < 0.1
    np.testing.assert_allclose(mfx[[RY, RX, RZ]], fx, atol=1e-3)
    # F_y: both inclined columns the same way (tilt), and the normal column still responds most to F_z
    assert fy[RX] == pytest.approx(fy[RY]) and fy[RX] > 5
    assert abs(fz[RZ]) > abs(fy[RZ]) > abs(fx[RZ])


def test_resistance_in_paper_ranges(pc, cfg):
    rest = NtypeSensor(cfg, backend="numpy").p.rest_ohm
    assert rest.tolist() == [50e3, 50e3, 25e3]  # ntype sect. 3.2: tops of 32-50 and 16-25 kOhm
    rz = pc["pure"]["Fz"]["r_kohm"][RZ]
    assert 15.0 <= rz <= 19.0  # paper: 16 kOhm at 4.8 N
    r_comp = pc["pure"]["Fx"]["r_kohm"][RY]  # the inclined column compressed by 4.8 N of F_x
    assert 30.0 <= r_comp <= 36.0  # paper: 32 kOhm at 4.8 N


def test_crosstalk_falls_with_distance(pc):
    c = pc["crosstalk_pct"]
    assert c["0cm"] == pytest.approx(100.0)
    assert c["1cm"] > c["2cm"] > c["3cm"] > c["4cm"] >= 0
    assert c["1cm"] > 15.0 and c["2cm"] > 1.0 and c["3cm"] < 2.0  # ntype sect. 3.3: significant within 1-2 cm


def test_warp_matches_numpy(cfg):
    rng = np.random.default_rng(3)
    E, T = 3, 15
    centres = rng.uniform(-0.05, 0.05, (E, 2))
    forces = np.column_stack([rng.uniform(-3, 3, (E, 2)), rng.uniform(0, 4.8, E)])
    load = patch_load(cfg, centres, forces, n_steps=T)
    a = NtypeSensor(cfg, backend="numpy").run_load(load, [1, 2, 3])
    b = NtypeSensor(cfg, backend="warp").run_load(load, [1, 2, 3])
    for k in ("displacement", "strain", "resistance", "force_element"):
        np.testing.assert_allclose(b[k], a[k], rtol=2e-5, atol=1e-9, err_msg=k)
    # float32 rounding differences may flip a reading across the 1 ohm readout quantum, no more
    np.testing.assert_allclose(b["resistance_measured"], a["resistance_measured"], rtol=0, atol=1.0)
    # the lag carries state across steps: after the ramp ends the resistance still creeps toward its relaxed value
    r = a["resistance"][:, :, :, RZ]
    moving = np.abs(r[:, -1] - r[:, -3]).max()
    assert moving > 0.0


def _one_indenter(cfg, force, shear_ratio, theta=0.0):
    from simulate.contact.mjcf import shear_stiffness_n_per_m
    from simulate.protocols.indenter import make_episode_protocol

    cfg = cfg.model_copy(deep=True)
    cfg.indenter.count = 1
    p = make_episode_protocol(cfg, 0)
    ind = p.params["indenters"][0]
    direction = np.array([np.cos(theta), np.sin(theta)])
    shear = shear_ratio * cfg.indenter.friction * force
    ind.update(xy_m=[-0.01, 0.01], force_n=force, stroke_xy_m=(shear / shear_stiffness_n_per_m(cfg) * direction).tolist(),
               shear_target_n=(min(shear, cfg.indenter.friction * force) * direction).tolist())
    return cfg, p


@pytest.mark.parametrize("ratio", [0.5, 1.5])
def test_mujoco_stroke_gives_intended_shear_with_the_right_sign(cfg, ratio):
    from simulate.contact.load_field import run_episodes

    c1, p = _one_indenter(cfg, 3.0, ratio)
    b = run_episodes(c1, [p])
    ind = p.params["indenters"][0]
    k = int(np.ceil((ind["t_stroke_s"][1] + 0.05) * c1.sampling.sample_rate_hz))
    fx, fy, fz = b.contact_force_n[0, k]
    assert fz == pytest.approx(3.0, rel=0.01)
    want = min(ratio, 1.0) * c1.indenter.friction * 3.0  # stick below the cone, slides at mu N above it
    assert fx == pytest.approx(want, rel=0.02) and abs(fy) < 1e-3
    out = NtypeSensor(c1, backend="numpy").run_load(b, [0])
    m = 3 * 6 + 2  # the element centred at (-1 cm, +1 cm)
    lab = out["force_element"][0, k, m]
    assert lab[0] == pytest.approx(fx, rel=1e-4) and lab[2] == pytest.approx(fz, rel=1e-4)
    r = out["resistance"][0, k, m] / NtypeSensor(c1, backend="numpy").p.rest_ohm - 1
    assert r[RX] > r[RY]  # +F_x stretches column 3 relative to column 1
    assert r[RZ] < 0  # the press shortens the normal column


def test_default_preset_has_paper_dataset_shape(cfg):
    frames = round((cfg.protocol.settle_s + cfg.protocol.duration_s) * cfg.sampling.sample_rate_hz)
    assert cfg.generation.episodes * frames == 3000  # ntype sect. 3.2: 3000 samples
    s = NtypeSensor(cfg, backend="numpy")
    out = s.run_load(patch_load(cfg, np.zeros((1, 2)), np.array([[0.0, 0.0, 1.0]]), n_steps=4), [0])
    assert out["resistance"].shape == out["force_element"].shape == (1, 4, 36, 3)
    np.testing.assert_allclose(out["force_element"].sum(2), out["force"], atol=1e-6)


@pytest.mark.parametrize(
    "override, expected",
    [
        ("sensor.element.column_area_m2=-1", "field 'sensor.element.column_area_m2'"),
        ("sensor.layer.depth_m=3 N", "field 'sensor.layer.depth_m' takes a value in m units"),
        ("sensor.resistance.rest_normal_ohm=0", "field 'sensor.resistance.rest_normal_ohm'"),
        ("sensor.elemnt.x=1", "unknown field 'sensor.elemnt' (did you mean 'element'?)"),
        ("sensor.family=nope", "field 'sensor.family': 'nope' is not a sensor family"),
        ("indenter.count=9", "field 'indenter.count'"),
    ],
)
def test_bad_parameter_one_line_error(override, expected):
    with pytest.raises(ConfigError) as exc:
        load_scene("ntype", [override])
    assert expected in str(exc.value) and "\n" not in str(exc.value)


def test_coplanar_columns_without_filler_rejected():
    with pytest.raises(ConfigError, match="sensor.element.inclined_azimuth_deg"):
        load_scene("ntype", ["sensor.element.inclined_azimuth_deg=0", "sensor.element.filler_stiffness_n_per_m=0"])

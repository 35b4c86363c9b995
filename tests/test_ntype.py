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
    assert np.all(fz < 0) and fz[RZ] < 1.5 * fz[RX]
    # crossed reading: +F_x shortens column 3 (R_x falls, as the paper's 50 -> 32 kOhm), leaves column 1 alone;
    # -F_x stretches it; F_y is the same with the roles of columns 3 and 1 swapped (x <-> y symmetry)
    assert fx[RX] < -20 and abs(fx[RY]) < 1 and mfx[RX] > 20
    np.testing.assert_allclose(fy[[RY, RX, RZ]], fx, atol=1e-3)
    # the normal column: weakly coupled to shear (ntype sect. 3.2), through the column geometry alone
    assert abs(fx[RZ]) < 0.03 * abs(fz[RZ]) and abs(fy[RZ]) < 0.03 * abs(fz[RZ])


def _rel_change(cfg, F):
    from sensors.ntype.model import ntype_params

    p = ntype_params(cfg)
    u = p.compliance @ np.asarray(F, float)
    e = p.normals @ u / p.lengths_m
    return (1 + e) ** 2 * np.exp(p.beta * e) - 1


@pytest.mark.parametrize("reading", ["crossed", "coplanar", "eq8"])
def test_column_reading_decides_what_each_column_observes(cfg, reading):
    """The consequence of each reading of Figure 1 / eq. 8: which force component moves which column
    (1 N along x, y, -z; "observes" = more than 1 % change)."""
    c = load_scene("ntype", [f"sensor.element.reading={reading}"])
    obs = np.array([np.abs(_rel_change(c, F)) > 0.01 for F in ([1, 0, 0], [0, 1, 0], [0, 0, -1])])  # [component, column]
    want = {"crossed": [[1, 0, 0], [0, 1, 0], [1, 1, 1]],   # R_x: F_x, F_z; R_y: F_y, F_z; R_z: F_z
            "coplanar": [[1, 1, 0], [0, 0, 0], [1, 1, 1]],  # nothing observes F_y
            "eq8": [[1, 1, 0], [1, 1, 0], [1, 1, 1]]}[reading]  # both inclined columns mix F_x and F_y
    np.testing.assert_array_equal(obs.astype(int), want)
    # R_z and shear: zero by symmetry where the inclined columns' projections oppose (coplanar: F_x), else the
    # small geometric coupling of the columns against the filler block
    rz = [abs(_rel_change(c, F)[RZ]) for F in ([1, 0, 0], [0, 1, 0], [0, 0, -1])]
    assert max(rz[:2]) < 0.03 * rz[2]
    if reading == "coplanar":
        assert rz[0] < 1e-9 and rz[1] < 1e-9


def test_decoupled_reading_is_sect_2_3_and_gives_the_paper_ranges():
    """Reading "decoupled" with DECOUPLED_ELEMENT (no filler, rho constant): each column observes its own component
    only, strained by F / (E S) (eq. 5), so 4.8 N puts R_x, R_y at 50 (1 - 0.197)^2 = 32.3 kOhm and R_z at 16.1
    kOhm, the paper's ranges (sect. 3.2), and the element is linear in its displacement (eq. 4)."""
    from scenes.ntype_config import DECOUPLED_ELEMENT

    c = load_scene("ntype", DECOUPLED_ELEMENT)
    obs = np.array([np.abs(_rel_change(c, F)) > 1e-9 for F in ([1, 0, 0], [0, 1, 0], [0, 0, -1])])
    np.testing.assert_array_equal(obs.astype(int), np.eye(3, dtype=int))
    e = 4.8 / (c.sensor.element.youngs_modulus_pa * c.sensor.element.column_area_m2)
    assert e == pytest.approx(0.1967, abs=1e-4)
    full = [_rel_change(c, F) for F in ([4.8, 0, 0], [0, 4.8, 0], [0, 0, -4.8])]
    assert 50e3 * (1 + full[0][RX]) == pytest.approx(32.26e3, rel=1e-3)
    assert 50e3 * (1 + full[1][RY]) == pytest.approx(32.26e3, rel=1e-3)
    assert 25e3 * (1 + full[2][RZ]) == pytest.approx(16.13e3, rel=1e-3)


def test_normal_column_shear_coupling_follows_the_column_stiffness(cfg):
    """The R_z change under pure F_x comes from the inclined columns' off-diagonal stiffness: doubling the
    columns' modulus about doubles it (the filler block alone would leave it at zero)."""
    a = abs(_rel_change(cfg, [1, 0, 0])[RZ])
    b = abs(_rel_change(load_scene("ntype", ["sensor.element.youngs_modulus_pa=12.2 MPa"]), [1, 0, 0])[RZ])
    assert a > 0 and 1.7 < b / a < 2.3


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
    assert r[RX] < r[RY]  # +F_x shortens column 3, not column 1
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
    with pytest.raises(ConfigError, match="sensor.element.reading"):
        load_scene("ntype", ["sensor.element.reading=coplanar", "sensor.element.filler_shear_modulus_pa=0"])


# ------------------------------------------------------------------------------------------ scanned readout

@pytest.mark.parametrize("scheme", ["floating", "grounded", "feedback"])
def test_network_solve_equals_direct_kirchhoff(scheme):
    from sensors.ntype.reference import scan_kirchhoff_numpy
    from sensors.ntype.scan import scan_apparent, wire_map

    rng = np.random.default_rng(5)
    R = rng.uniform(16e3, 50e3, (2, 36, 3))
    up, lo, U, L = wire_map(6, 6)
    a = scan_apparent(R, 6, 6, scheme, 5.0, 100.0, 1e3)
    b = np.stack([scan_kirchhoff_numpy(r, up, lo, U, L, scheme, 5.0, 100.0, 1e3) for r in R])
    np.testing.assert_allclose(a, b, rtol=1e-9)
    assert U == L == 12 and len({(u, l) for u, l in zip(up.ravel(), lo.ravel())}) == 108  # one column per crossing


@pytest.mark.parametrize("nx,ny,r_on", [(6, 6, 100.0), (6, 6, 0.0), (6, 6, 5e3), (5, 3, 100.0)])
def test_scan_feedback_warp_equals_numpy(nx, ny, r_on):
    """The Warp kernel (one thread per frame, Gaussian elimination with partial pivoting in float64) reads what the
    numpy batched Schur solve reads, on the CPU device, for ideal to poor switches and a non-square array."""
    from sensors.ntype.scan import scan_apparent

    rng = np.random.default_rng(11)
    R = rng.uniform(5e3, 80e3, (40, nx * ny, 3))
    R[:3] = rng.uniform(16e3, 50e3, 3)  # also frames where every column reads alike (symmetric networks)
    a = scan_apparent(R, nx, ny, "feedback", 5.0, r_on, 1e3)
    b = scan_apparent(R, nx, ny, "feedback", 5.0, r_on, 1e3, backend="warp", device="cpu")
    np.testing.assert_allclose(b, a, rtol=1e-9)
    assert np.abs(b / R - 1).max() > (1e-3 if r_on > 0 else -1)  # the scan did act (sneak residue with R_on > 0)


def test_scan_warp_backend_keeps_numpy_for_the_comparison_schemes():
    from sensors.ntype.scan import scan_apparent

    R = np.random.default_rng(4).uniform(16e3, 50e3, (2, 36, 3))
    for s in ("ideal", "floating", "grounded"):
        np.testing.assert_array_equal(scan_apparent(R, 6, 6, s, 5.0, 100.0, 1e3, backend="warp"),
                                      scan_apparent(R, 6, 6, s, 5.0, 100.0, 1e3))


def _sneak(scheme):
    """Relative change of the reading of an unloaded element's columns when every other column falls by 30 %."""
    from sensors.ntype.scan import scan_apparent

    R0 = np.ones((1, 36, 3)) * np.array([50e3, 50e3, 25e3])
    R1 = R0 * 0.7
    R1[0, 14] = R0[0, 14]
    a, b = (scan_apparent(R, 6, 6, scheme, 5.0, 100.0, 1e3)[0, 14] for R in (R0, R1))
    return np.abs(b / a - 1).max(), np.abs(a / R0[0, 14] - 1).max()


def test_sneak_paths_change_readings_and_grounding_suppresses_them():
    ideal, floating, grounded, feedback = (_sneak(s) for s in ("ideal", "floating", "grounded", "feedback"))
    assert ideal == (0.0, 0.0)
    assert floating[1] > 0.5 and floating[0] > 0.15  # open lines: the reading is mostly the sneak network
    assert grounded[0] < 0.6 * floating[0]  # grounded unselected lines drain the sneak currents
    assert feedback[0] < 0.25 * grounded[0] and feedback[0] > 1e-3  # virtual ground: only R_on leaves a residue


def test_feedback_with_ideal_switches_is_the_ideal_ohmmeter():
    from sensors.ntype.scan import scan_apparent

    R = np.random.default_rng(2).uniform(16e3, 50e3, (3, 36, 3))
    np.testing.assert_allclose(scan_apparent(R, 6, 6, "feedback", 5.0, 0.0, 1e3), R, rtol=1e-6)


def test_scanned_dataset_differs_from_ideal_readout(cfg):
    rng = np.random.default_rng(4)
    E, T = 2, 6
    load = patch_load(cfg, rng.uniform(-0.04, 0.04, (E, 2)), np.column_stack([rng.uniform(0, 3, (E, 2)), [4.0, 3.0]]), n_steps=T)
    quiet = ["sensor.readout.noise_fraction=0", "sensor.readout.resolution_ohm=0"]
    out = {s: NtypeSensor(load_scene("ntype", [f"sensor.readout.scan={s}", *quiet]), backend="numpy").run_load(load, [0, 1])
           for s in ("ideal", "feedback", "floating")}
    np.testing.assert_allclose(out["ideal"]["resistance_measured"], out["ideal"]["resistance"], rtol=1e-6)
    dev = {s: np.abs(out[s]["resistance_measured"] / out[s]["resistance"] - 1) for s in ("feedback", "floating")}
    assert 0.01 < dev["feedback"].mean() < 0.2 and dev["floating"].mean() > 0.5


# ------------------------------------------------------------------------------------------ paper protocol

def test_paper_protocol_labels_and_sample_count():
    """ntype sect. 3.2: 3000 samples of 36 x 3 forces, each component in [0, 4.8] N, every element loaded."""
    from scenes.ntype_config import PAPER_PROTOCOL
    from sensors.data.manifest import episode_seed
    from simulate.contact.load_field import run_episodes
    from simulate.protocols.indenter import make_episode_protocol

    c = load_scene("ntype", PAPER_PROTOCOL)
    protos = [make_episode_protocol(c, episode_seed(0, k)) for k in range(3)]
    assert c.generation.episodes * protos[0].n_samples == 3000
    b = run_episodes(c, protos)
    out = NtypeSensor(c, backend="numpy").run_load(b, [0, 1, 2])
    lab = out["force_element"]
    np.testing.assert_allclose(lab, np.stack([p.params["forces_n"] for p in protos]), atol=1e-5)
    assert lab.min() >= 0.0 and lab.max() <= 4.8 and (lab.max((0, 1)) > 4.0).all()  # every element, every component
    assert lab.shape == (3, 20, 36, 3)
    rz = out["resistance"][..., RZ] / 1e3
    assert rz.min() > 15.0 and rz.max() <= 25.0  # ntype sect. 3.2: R_z in [16, 25] kOhm


@pytest.mark.parametrize("dist, extra, mean_n", [("uniform", [], 2.4), ("beta", [], 0.6),
                                                 ("beta", ["protocol.force_beta_alpha=2", "protocol.force_beta_beta=2"], 2.4)])
def test_element_loads_force_distribution(dist, extra, mean_n):
    """protocol.force_distribution: the drawn components keep to [amplitude_min, amplitude_max], their mean and
    spread are the stated distribution's (uniform: mean 2.4 N, sd 4.8 / sqrt 12; beta(a, b) x 4.8 N: mean
    4.8 a / (a + b)), the draw is a function of the seed, and the uniform draw is the paper task's default."""
    from scenes.ntype_config import PAPER_PROTOCOL
    from simulate.protocols.element_loads import component_mean_n
    from simulate.protocols.indenter import make_episode_protocol

    c = load_scene("ntype", [*PAPER_PROTOCOL, f"protocol.force_distribution={dist}", *extra])
    assert load_scene("ntype", PAPER_PROTOCOL).protocol.force_distribution == "uniform"
    f = np.concatenate([make_episode_protocol(c, s).params["forces_n"] for s in range(8)])  # 8 x 20 x 36 x 3
    assert f.min() >= 0.0 and f.max() <= 4.8 and f.shape == (160, 36, 3)
    assert component_mean_n(c.protocol) == pytest.approx(mean_n)
    se = f.std() / np.sqrt(f[..., 0].size)
    for k in range(3):  # each component on its own: 5760 draws, mean within 4 standard errors
        assert abs(f[..., k].mean() - mean_n) < 4 * se
    p = c.protocol
    a, b = (1.0, 1.0) if dist == "uniform" else (p.force_beta_alpha, p.force_beta_beta)
    sd = 4.8 * np.sqrt(a * b / ((a + b) ** 2 * (a + b + 1)))
    assert f.std() == pytest.approx(sd, rel=0.05)
    np.testing.assert_array_equal(make_episode_protocol(c, 3).params["forces_n"], f[60:80])  # same seed, same draw
    assert not np.array_equal(make_episode_protocol(c, 4).params["forces_n"], f[60:80])

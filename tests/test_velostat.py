"""velostat family: creep physics, readout, position decoding, clustering, Warp == numpy, config errors."""

import numpy as np
import pytest

from scenes import ConfigError, load_scene
from sensors.registry import make_sensor
from simulate.characterize import velostat as vc
from simulate.protocols.compression_tester import knots_steps, ramp_s


@pytest.fixture(scope="module")
def cfg():
    return load_scene("velostat")


@pytest.fixture(scope="module")
def sensor(cfg):
    return make_sensor(cfg, "numpy")


@pytest.fixture(scope="module")
def report(cfg):
    return vc.characterize_velostat(cfg, backend="numpy", load="ideal")


def _press(cfg, sensor, level, speed_mm_min=3.0, hold=30.0, xy=(0.0, 0.0)):
    v = speed_mm_min * vc.MM_PER_MIN
    t, f = knots_steps(cfg, [level], [hold], [v], [0.0])[:2]
    p = vc._proto(cfg, t, f, np.asarray(xy), ramp_s(cfg, level, v) + hold + 1.0)
    _, out = vc.run(cfg, sensor, [p], "ideal")
    i0 = vc._idx(cfg, ramp_s(cfg, level, v))
    i1 = i0 + int(hold * cfg.sampling.sample_rate_hz) - 1
    return out, i0, i1


def test_creep_amplitude_falls_with_force(cfg, sensor):
    rel = []
    for lv in (1.0, 3.0, 5.0, 10.0):
        out, i0, i1 = _press(cfg, sensor, lv)
        r = out["resistance"][0].astype(float)  # noise-free
        assert r[i1] < r[i0]  # resistance keeps falling under constant force
        rel.append((r[i0] - r[i1]) / r[i0])
    assert rel == sorted(rel, reverse=True) and rel[0] > 1.5 * rel[-1]


def test_creep_amplitude_grows_with_loading_speed(cfg, sensor):
    rel = []
    for v in (1.0, 3.0, 6.0):
        out, i0, i1 = _press(cfg, sensor, 3.0, speed_mm_min=v)
        r = out["resistance"][0].astype(float)
        rel.append((r[i0] - r[i1]) / r[i0])
    assert rel == sorted(rel) and rel[-1] > 1.2 * rel[0]


def test_r_at_full_load_nearly_speed_independent(cfg, sensor):
    """Fig. 5: creep during loading is negligible, R at the full-load point about equal at 1-6 mm/min."""
    r0 = []
    for v in (1.0, 6.0):
        out, i0, _ = _press(cfg, sensor, 3.0, speed_mm_min=v)
        r0.append(float(out["resistance"][0, i0]))
    assert abs(r0[0] - r0[1]) / max(r0) < 0.15


def test_creep_lives_in_the_holds(cfg, sensor):
    """Along a constant-rate ramp the film reads as without creep; in the hold it creeps (aging)."""
    c0 = load_scene("velostat", ["sensor.creep.amplitude=0"])
    s0 = make_sensor(c0, "numpy")
    v = 3 * vc.MM_PER_MIN
    t, f = knots_steps(cfg, [7.0], [20.0], [v], [0.0])[:2]
    p = vc._proto(cfg, t, f, np.zeros(2), ramp_s(cfg, 7.0, v) + 21.0)
    pr = vc.ideal_load(cfg, [p]).pressure_pa
    g, g0 = sensor.conductance(pr)[0].sum(-1), s0.conductance(pr)[0].sum(-1)
    i0 = vc._idx(cfg, ramp_s(cfg, 7.0, v))
    on = slice(vc._idx(cfg, 0.5), i0)
    np.testing.assert_allclose(g[on], g0[on], rtol=0.02)  # loading: no creep
    assert g[i0 + 150] > 1.2 * g0[i0 + 150]  # 15 s into the hold: > 20 % more conductance


def test_creep_error_at_7n_in_band(report):
    assert 2.5 <= report.metrics["creep_error_7n_hold_n"] <= 6.0  # paper: up to 5 N (sect. 5.4)
    assert 3.5 <= report.metrics["creep_error_7n_staircase_n"] <= 6.5  # paper: up to 5 N (Fig. 22a)


def test_clustering_elbow_about_5(report):
    assert 4 <= report.metrics["cluster_elbow"] <= 6  # paper: about 5 (film domains, an estimate)
    assert sum(report.metrics["cluster_sizes"]) == 36


def test_position_error_grows_at_low_force(report):
    for wiring in ("4-wire", "5-wire"):
        e = report.metrics["position_error_mm"][wiring]
        assert e["0.5N"][0] > e["2N"][0] > 0 and e["0.5N"][0] > e["15N"][0]
        assert e["1N"][1] < 5.0  # paper: max 3 mm


def test_two_contacts_give_conductance_weighted_position(report):
    x = report.metrics["two_contacts_x_mm"]
    assert abs(x["measured"] - x["conductance_weighted"]) < 1.5  # within ~1 mm (probe load, ADC)
    assert -30.0 < x["conductance_weighted"] < 30.0  # between the contacts (where depends on the film's domains)


def test_two_contacts_synthetic_fields():
    """Two equal contacts at mirrored positions decode near the middle; unequal ones toward the stronger
    (a film of one domain: with several, equal presses differ by the domains' resistivity)."""
    cfg = load_scene("velostat", ["sensor.film.domains=1"])
    sensor = make_sensor(cfg, "numpy")
    N = cfg.pad.n_taxels
    xy = sensor.xy
    a = np.argmin(np.linalg.norm(xy - [-0.035, 0.005], axis=1))
    b = np.argmin(np.linalg.norm(xy - [0.035, 0.005], axis=1))
    pr = np.zeros((2, 3, N), np.float32)
    pr[0, :, a] = pr[0, :, b] = 5e4
    pr[1, :, a], pr[1, :, b] = 2e4, 8e4
    out = sensor.run(pr, [0, 1])
    g = sensor.conductance(pr)
    x0 = out["position_measured"][0, -1, 0]
    xg = (g[1, -1] * xy[:, 0]).sum() / g[1, -1].sum()
    x1 = out["position_measured"][1, -1, 0]
    assert abs(x0 - (xy[a, 0] + xy[b, 0]) / 2) < 2e-3
    assert x1 > 0.01 and abs(x1 - xg) < 2e-3


def test_oversampled_samples_carry_less_noise_and_more_bits():
    """The force channel's reported sample averages 4^k conversions (ST AN2668): white noise / 2^k and k more
    bits on the same range. The same noise draw at 1 and 16 conversions (a factor 4 apart); a light press read
    through both: the 14-bit codes step 4x finer, and the measured R of a hold scatters ~4x less about its mean."""
    one = load_scene("velostat")  # the preset: one conversion per sample
    six = load_scene("velostat", ["sensor.readout.oversampling=16"])
    r1, r16 = one.sensor.readout, six.sensor.readout
    assert r16.oversampling == 16 and r16.sample_bits == r1.adc_bits + 2 == 14
    assert r16.sample_noise_v == pytest.approx(r1.noise_v / 4)
    a, b = make_sensor(one, "numpy"), make_sensor(six, "numpy")
    np.testing.assert_allclose(b.noise([5, 6], 400), a.noise([5, 6], 400) / 4, rtol=1e-6)
    assert a.rp.adc_bits == 12 and b.rp.adc_bits == 14 and b.attrs()["adc_oversampling"] == 16
    pr = np.zeros((1, 400, one.pad.n_taxels), np.float32)
    pr[0, :, 70] = 8e4  # a firm press on one taxel: R of a few hundred ohm to a kilohm, held
    ra, rb = a.run(pr, [7])["resistance_measured"][0, 100:], b.run(pr, [7])["resistance_measured"][0, 100:]
    sa, sb = np.std(np.diff(ra)), np.std(np.diff(rb))
    assert 2.5 < sa / sb < 6.0  # noise 1/4 (creep in the hold adds the same slow drift to both)
    assert b.run(pr, [7])["adc"].max() < 2 ** 14
    with pytest.raises(ConfigError, match="sensor.readout.adc_bits' \\+ the oversampling's bits must be <= 24"):
        load_scene("velostat", ["sensor.readout.adc_bits=24", "sensor.readout.oversampling=4"])


def test_compliance_limit_clips(cfg):
    c = cfg.model_copy(deep=True)
    c.sensor.readout.current_a = 1e-3  # 1 mA: 3 V compliance reached at 3 kohm
    s = make_sensor(c, "numpy")
    pr = np.zeros((1, 3, c.pad.n_taxels), np.float32)
    pr[0, 1, 70] = 1e4  # a light press: ~20 kohm film
    out = s.run(pr, [0])
    assert out["voltage_true"][0, 1, 0] == pytest.approx(c.sensor.readout.compliance_v)
    assert out["resistance"][0, 1] * 1e-3 > 3.0  # the true resistance is beyond what the source can drive
    assert out["resistance_measured"][0, 1] == pytest.approx(3.0 / 1e-3, rel=0.01)
    assert np.isnan(out["position_measured"][0, 0]).all()  # unloaded: no touch, no position


@pytest.mark.parametrize("model", ["aging", "spectrum"])
def test_warp_matches_numpy(model):
    cfg = load_scene("velostat", [f"sensor.creep.model={model}"])
    rng = np.random.default_rng(3)
    E, T, N = 3, 80, cfg.pad.n_taxels
    pr = np.zeros((E, T, N), np.float32)
    ramp = np.minimum(np.arange(T) / 20.0, 1.0)[:, None]
    idx = rng.choice(N, size=(E, 4), replace=False)
    for e in range(E):
        pr[e][:, idx[e]] = ramp * rng.uniform(5e3, 1.5e5, 4)
    pr[:, 60:] *= 0.3  # partial unload
    w = make_sensor(cfg, "warp").run(pr, [1, 2, 3])
    n = make_sensor(cfg, "numpy").run(pr, [1, 2, 3])
    np.testing.assert_allclose(w["resistance"], n["resistance"], rtol=2e-4)
    np.testing.assert_allclose(w["voltage_true"], n["voltage_true"], rtol=2e-4, atol=1e-6)
    assert np.abs(w["adc"].astype(int) - n["adc"].astype(int)).max() <= 1
    np.testing.assert_allclose(
        make_sensor(cfg, "warp").conductance(pr), make_sensor(cfg, "numpy").conductance(pr), rtol=2e-4, atol=1e-12
    )


@pytest.mark.parametrize(
    "override, expected",
    [
        ("sensor.readout.sheet_resistance_ohm=50", "sensor.readout.sheet_resistance_ohm"),
        ("sensor.film.exponnt=1", "unknown field 'sensor.film.exponnt' (did you mean 'exponent'?)"),
        ("sensor.readout.compliance_v=9", "field 'sensor.readout.compliance_v'"),
        ("sensor.creep.times_s=[1,2,3,4,5,6,7,8,9]", "field 'sensor.creep.times_s'"),
        ("protocol.hold_min_s=40", "protocol.hold_min_s"),
        ("protocol.loading_speeds_m_per_s=[-1]", "protocol.loading_speeds_m_per_s"),
        ("sensor.readout.oversampling=8", "field 'sensor.readout.oversampling' must be a power of 4 (1, 4, 16"),
    ],
)
def test_bad_parameter_one_line_naming_field(override, expected):
    with pytest.raises(ConfigError) as exc:
        load_scene("velostat", [override])
    assert expected in str(exc.value) and "\n" not in str(exc.value)


def test_protocols_and_film_field(cfg):
    from simulate.protocols.indenter import make_episode_protocol, target_waveform

    kinds = set()
    for s in range(12):
        p = make_episode_protocol(cfg, s)
        kinds.add(p.params["kind"])
        t = np.arange(p.n_samples) / cfg.sampling.sample_rate_hz
        f = target_waveform(p, cfg, t)
        assert f.min() >= 0 and 1.0 <= f.max() <= 15.0 + 1e-9
        assert np.all(np.abs(p.offset_xy_m) < 0.06)
    assert kinds == {"velostat_steps", "velostat_staircase", "velostat_calibration"}
    a, b = make_sensor(cfg, "numpy"), make_sensor(load_scene("velostat", ["sensor.film.field_seed=9"]), "numpy")
    assert not np.allclose(a.z_g, b.z_g)
    assert np.allclose(a.z_g, make_sensor(cfg, "numpy").z_g)  # one part per seed


def _float64_field(cfg, rng, E, T):
    """A float64 pressure field [E, T, N] as the load field makes it: a few loaded taxels per episode under
    ramp-and-hold presses up to 150 kPa (values not exact in float32), the first samples and some frames unloaded,
    and tiny negative values (-1e-12 Pa, rounding of the Winkler split) that the film and the sums clip."""
    N = cfg.pad.n_taxels
    pr = np.zeros((E, T, N))
    t = np.arange(T)
    for e in range(E):
        idx = rng.choice(N, 5, replace=False)
        pr[e][:, idx] = np.minimum(t / 17.0, 1.0)[:, None] * rng.uniform(1e3, 1.5e5, 5) * (1 + 1e-9 * rng.random((T, 5)))
        pr[e, :8] = 0.0
        pr[e, T // 2 : T // 2 + 5] = 0.0
    pr[:, :, 0] -= 1e-12
    return pr


def test_device_path_equals_host_path():
    """The GPU path (`run_device`: film input, force and centroid made from the float64 field where it lies, only
    the (E, T, <= 3) outputs copied back) on Warp's CPU device equals `run` on the host copy of the field: bit for
    bit but force and contact_xy (float64 sums in another order, then rounded to float32: within 1 float32 ulp)."""
    import warp as wp

    from sensors.velostat.kernels import frame_sums_device
    from sensors.velostat.reference import force_centroid_numpy

    cfg = load_scene("velostat")
    s = make_sensor(cfg, "warp", "cpu")
    E, T = 3, 90
    pr = _float64_field(cfg, np.random.default_rng(5), E, T)
    seeds = [4, 5, 6]
    host = s.run(pr, seeds)
    dev = s.run_device(wp.array(pr.reshape(E * T, -1), dtype=wp.float64, device="cpu"), seeds, (E, T))
    assert list(dev) == list(host)
    assert np.isnan(host["contact_xy"]).any() and np.isfinite(host["contact_xy"]).any()
    for k in host:
        if k in ("force", "contact_xy"):
            np.testing.assert_allclose(dev[k], host[k], rtol=2.4e-7, atol=1e-12, err_msg=k)
            np.testing.assert_array_equal(np.isnan(dev[k]), np.isnan(host[k]), err_msg=k)
        else:
            np.testing.assert_array_equal(dev[k], host[k], err_msg=k)
    # the frame-sums kernel against its numpy reference: float64 values to 1e-12, the film input exactly
    p32, sums, unit = frame_sums_device(wp.array(pr.reshape(E * T, -1), dtype=wp.float64, device="cpu"), s.xy, s.area,
                                        units=s.unit_grid())
    fz, cxy = force_centroid_numpy(pr, s.xy, s.area)
    np.testing.assert_array_equal(p32.numpy().reshape(E, T, -1), pr.astype(np.float32))
    # the unit index made in the kernel is unit_of's on the kernel's own centroids, every frame (-1 unloaded)
    np.testing.assert_array_equal(unit.numpy().reshape(E, T), s.unit_of(sums.numpy().reshape(E, T, 3)[..., 1:]))
    assert (unit.numpy() == -1).any() and len(np.unique(unit.numpy())) > 3
    got = sums.numpy().reshape(E, T, 3)
    np.testing.assert_allclose(got[..., 0], fz, rtol=1e-12, atol=0)
    np.testing.assert_allclose(got[..., 1:], cxy, rtol=1e-12, atol=1e-15)
    assert fz.max() > 10.0  # the presses reach newtons: a loaded field was compared

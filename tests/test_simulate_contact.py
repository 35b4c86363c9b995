"""simulate.contact.load_field: batched MuJoCo episodes -> per-taxel load field. Physics asserted, short episodes."""

import dataclasses

import numpy as np
import pytest

from scenes import load_scene
from simulate.contact.load_field import load_field, run_episodes
from simulate.protocols.indenter import make_episode_protocol

FAST = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1"]


def _k_winkler(cfg):
    return cfg.pad.youngs_modulus_pa * cfg.indenter.size_x_m * cfg.indenter.size_y_m / cfg.pad.thickness_m


@pytest.fixture(scope="module")
def disp():
    cfg = load_scene("cnt_pdms", FAST)
    protos = [make_episode_protocol(cfg, s) for s in range(4)]
    return cfg, protos, run_episodes(cfg, protos)


def _penetration(cfg, batch):
    return cfg.pad.thickness_m - batch.indenter_pos_m[..., 2]


def test_shapes(disp):
    cfg, protos, b = disp
    E, T, N = len(protos), protos[0].n_samples, cfg.pad.n_taxels
    assert b.time_s.shape == (T,) and b.time_s[1] == pytest.approx(1 / cfg.sampling.sample_rate_hz)
    assert b.target.shape == (E, T) and b.indenter_pos_m.shape == (E, T, 3) and b.contact_force_n.shape == (E, T, 3)
    assert b.deformation_m.shape == b.pressure_pa.shape == (E, T, N) and b.shear_pa.shape == (E, T, N, 2)
    assert b.taxel_xy_m.shape == (N, 2)
    assert b.taxel_area_m2 * N == pytest.approx(cfg.pad.size_x_m * cfg.pad.size_y_m)
    # the indenter holds its x/y offset
    for e, p in enumerate(protos):
        np.testing.assert_allclose(b.indenter_pos_m[e, :, :2], np.broadcast_to(p.offset_xy_m, (T, 2)), atol=1e-7)


def test_penetration_tracks_commanded_displacement(disp):
    """Penetration follows d(t) within 2 % of d0 everywhere (measured: 0.12 %), and within 1 % at the peak."""
    cfg, protos, b = disp
    pen = _penetration(cfg, b)
    d0 = np.array([p.amplitude for p in protos])
    assert np.all(np.abs(pen - b.target).max(axis=1) < 0.02 * d0)
    np.testing.assert_allclose(pen.max(axis=1), d0, rtol=0.01)
    np.testing.assert_allclose(b.target.max(axis=1), d0, rtol=1e-3)


def test_deformation_peak_is_d0_under_indenter_and_decays(disp):
    cfg, protos, b = disp
    xy = b.taxel_xy_m
    for e, p in enumerate(protos):
        k = int(np.argmax(b.target[e]))
        field = b.deformation_m[e, k]
        centre = np.argmin(((xy - p.offset_xy_m) ** 2).sum(1))
        assert field[centre] == pytest.approx(p.amplitude, rel=0.02)
        assert field.max() == pytest.approx(field[centre], rel=1e-9)  # largest under the indenter
        dist = np.abs(xy - p.offset_xy_m).max(1)  # Chebyshev distance from the indenter axis
        half = cfg.indenter.size_x_m / 2
        assert field[dist > half + 4 * cfg.pad.spread_length_m].max() < 0.02 * p.amplitude
        # along the taxel row through the centre, outward from the footprint edge, it never increases
        iy, ix = divmod(centre, cfg.pad.taxels_x)
        row = b.deformation_m[e, k].reshape(cfg.pad.taxels_y, cfg.pad.taxels_x)[iy]
        assert np.all(np.diff(row[ix:]) <= 1e-15) and np.all(np.diff(row[: ix + 1]) >= -1e-15)
        assert row[-1] < row[ix] and row[0] < row[ix]


def test_force_balance_and_winkler_force(disp):
    cfg, protos, b = disp
    fn = b.contact_force_n[..., 2]
    np.testing.assert_allclose((b.pressure_pa * b.taxel_area_m2).sum(-1), fn, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose((b.shear_pa * b.taxel_area_m2).sum(-2), b.contact_force_n[..., :2], rtol=1e-6, atol=1e-12)
    assert np.all(b.pressure_pa >= 0)
    pen = _penetration(cfg, b)
    k = _k_winkler(cfg)
    for e, p in enumerate(protos):
        # F ~ k d within 1 % of full scale k d0 (the light contact damping adds C v; measured ~0.4 %)
        assert np.abs(fn[e] - k * pen[e]).max() < 0.01 * k * p.amplitude
        assert fn[e].max() == pytest.approx(k * p.amplitude, rel=0.02)
        # loading branch: force non-decreasing while the command rises
        rising = np.flatnonzero(np.diff(b.target[e]) > 0)
        assert np.all(np.diff(fn[e])[rising] >= -1e-9)
        assert fn[e, 0] == pytest.approx(0.0, abs=1e-9)


def test_harder_press_gives_larger_deformation_and_force():
    cfg = load_scene("cnt_pdms", FAST)
    p = make_episode_protocol(cfg, 3)
    soft = dataclasses.replace(p, amplitude=5e-5)
    hard = dataclasses.replace(p, amplitude=1.5e-4)
    b = run_episodes(cfg, [soft, hard])
    d_peak = b.deformation_m.max(axis=(1, 2))
    f_peak = b.contact_force_n[..., 2].max(axis=1)
    assert d_peak[1] > d_peak[0] and f_peak[1] > f_peak[0]
    assert d_peak[1] / d_peak[0] == pytest.approx(3.0, rel=0.03)
    assert f_peak[1] / f_peak[0] == pytest.approx(3.0, rel=0.03)


def test_deterministic_and_thread_invariant(disp):
    cfg, protos, b = disp
    again = run_episodes(cfg, protos)
    threaded = run_episodes(cfg, protos, threads=2)
    for other in (again, threaded):
        for name in ("indenter_pos_m", "contact_force_n", "deformation_m", "pressure_pa", "shear_pa"):
            np.testing.assert_array_equal(getattr(other, name), getattr(b, name))


def test_mixed_n_samples_rejected():
    cfg = load_scene("cnt_pdms", ["protocol.frequencies_hz=[1.0, 2.0]", "protocol.cycles=1"])
    protos = [make_episode_protocol(cfg, s) for s in range(20)]
    assert len({p.n_samples for p in protos}) == 2
    with pytest.raises(ValueError, match="n_samples"):
        run_episodes(cfg, protos)


def test_force_control_hold_settles_at_commanded_force():
    cfg = load_scene(
        "cnt_pdms",
        ["protocol.control=force", "protocol.kind=hold", "protocol.amplitude_min=1.0", "protocol.amplitude_max=5.0",
         "protocol.duration_s=1.0", "protocol.ramp_s=0.3"],
    )
    protos = [make_episode_protocol(cfg, s) for s in range(3)]
    b = run_episodes(cfg, protos)
    fn = b.contact_force_n[..., 2]
    late = b.time_s >= cfg.protocol.settle_s + cfg.protocol.ramp_s + 0.3
    for e, p in enumerate(protos):
        np.testing.assert_allclose(fn[e, late], p.amplitude, rtol=0.02)
        np.testing.assert_allclose(b.target[e, late], p.amplitude)
        # and the indenter sits at the Winkler depth F / k
        pen = _penetration(cfg, b)[e, late]
        np.testing.assert_allclose(pen, p.amplitude / _k_winkler(cfg), rtol=0.02)


def test_sphere_indenter_force_balance_and_peak_under_axis():
    cfg = load_scene("cnt_pdms", FAST + ["indenter.shape=sphere", "indenter.radius_m=0.005"])
    protos = [make_episode_protocol(cfg, s) for s in range(2)]
    b = run_episodes(cfg, protos)
    fn = b.contact_force_n[..., 2]
    np.testing.assert_allclose((b.pressure_pa * b.taxel_area_m2).sum(-1), fn, rtol=1e-6, atol=1e-12)
    for e, p in enumerate(protos):
        k = int(np.argmax(b.target[e]))
        assert fn[e, k] > 0
        field = b.deformation_m[e, k]
        nearest = np.argmin(((b.taxel_xy_m - p.offset_xy_m) ** 2).sum(1))
        assert np.argmax(field) == nearest
        assert field.max() < p.amplitude  # cell average of a cap smaller than the taxel


def test_load_field_distributes_tangential_force():
    """Synthetic pose + force: shear sums to the tangential force, pressure to the normal one, in proportion."""
    cfg = load_scene("cnt_pdms")
    pos = np.array([[[0.001, -0.002, -1e-4], [0.0, 0.0, 1e-4]]])  # second frame: not in contact
    force = np.array([[[0.5, -0.25, 3.0], [0.0, 0.0, 0.0]]])
    deform, pressure, shear = load_field(cfg, pos, force)
    area = cfg.pad.size_x_m * cfg.pad.size_y_m / cfg.pad.n_taxels
    assert (pressure[0, 0] * area).sum() == pytest.approx(3.0, rel=1e-9)
    np.testing.assert_allclose((shear[0, 0] * area).sum(0), [0.5, -0.25], rtol=1e-9)
    np.testing.assert_allclose(shear[0, 0, :, 0] / 0.5, pressure[0, 0] / 3.0, rtol=1e-9)
    assert np.all(deform[0, 1] == 0) and np.all(pressure[0, 1] == 0) and np.all(shear[0, 1] == 0)


def test_controls_made_in_chunks_equal_the_whole():
    """The GPU path makes controls chunk by chunk while the worlds step: every chunk equals those rows of the
    whole arrays (incl. the velocity feed-forward's differences at chunk borders and at both ends)."""
    from simulate.contact.load_field import episode_controls, sample_targets

    cfg = load_scene("cnt_pdms", FAST)
    protos = [make_episode_protocol(cfg, s) for s in range(3)]
    n = protos[0].n_samples
    nstep = (n - 1) * cfg.sampling.substeps
    ctrl, tgt = episode_controls(cfg, protos, nstep)
    for a, b in [(0, 1), (0, 37), (37, 401), (401, nstep), (nstep - 1, nstep)]:
        c, t = episode_controls(cfg, protos, nstep, slice(a, b))
        np.testing.assert_array_equal(c, ctrl[:, a:b])
        np.testing.assert_array_equal(t, tgt[:, a:b])
    # the target at the sample times is the step target of the step the sensors are read after
    rows = np.arange(1, n) * cfg.sampling.substeps - 1
    np.testing.assert_array_equal(sample_targets(cfg, protos, n)[:, 1:], tgt[:, rows])


def test_load_batches_in_slices_equal_one_batch(disp):
    """The sensor stage goes slice by slice after one physics batch: each slice equals those episodes."""
    from simulate.contact.load_field import iter_load_batches

    cfg, protos, whole = disp
    parts = list(iter_load_batches(cfg, protos, slice_episodes=3))
    assert [sl for sl, _ in parts] == [slice(0, 3), slice(3, 4)]
    for sl, b in parts:
        for name in ("target", "indenter_pos_m", "contact_force_n", "deformation_m", "pressure_pa", "shear_pa"):
            np.testing.assert_array_equal(getattr(b, name), getattr(whole, name)[sl], err_msg=name)


def test_sensor_chain_on_device_fields_equals_host_fields():
    """cnt_pdms takes taxel fields left on the Warp device (GPU path) and gives the same outputs as from numpy."""
    from sensors.cnt_pdms.model import CntPdmsSensor
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field_kernels import load_field_warp

    init_warp()
    for control in ("displacement", "force"):
        cfg = load_scene("cnt_pdms", FAST + ["pad.taxels_x=4", "pad.taxels_y=3", "sensor.readout=taxel",
                                             f"protocol.control={control}"])
        rng = np.random.default_rng(1)
        E, T = 3, 60
        pos = np.stack([rng.uniform(-0.01, 0.01, (E, T)), rng.uniform(-0.01, 0.01, (E, T)), rng.uniform(-2e-4, 1e-5, (E, T))], -1)
        force = np.stack([rng.normal(0, 0.1, (E, T)), rng.normal(0, 0.1, (E, T)), rng.uniform(0, 4, (E, T))], -1)
        host = load_field_warp(cfg, pos, force, "cpu")
        dev = load_field_warp(cfg, pos, force, "cpu", to_host=False)
        base = dict(time_s=np.arange(T) / 100.0, target=np.zeros((E, T)), indenter_pos_m=pos, contact_force_n=force,
                    contact_points=np.zeros((E, T), np.int64), taxel_xy_m=np.zeros((12, 2)), taxel_area_m2=1e-5, control=control)
        from sensors.base import LoadBatch

        b_host = LoadBatch(deformation_m=host[0], pressure_pa=host[1], shear_pa=host[2], **base)
        b_dev = LoadBatch(deformation_m=dev[0], pressure_pa=dev[1], shear_pa=dev[2], **base)
        assert b_dev.fields_on_device and not b_host.fields_on_device
        for name in ("deformation_m", "pressure_pa", "shear_pa"):
            np.testing.assert_array_equal(getattr(b_dev.on_host(), name), getattr(b_host, name))
        s = CntPdmsSensor(cfg, backend="warp", device="cpu")
        a, b = s.run_load(b_host, [5, 6, 7]), s.run_load(b_dev, [5, 6, 7])
        assert a.keys() == b.keys() and a["adc"].std() > 0
        for k in a:
            np.testing.assert_array_equal(b[k], a[k], err_msg=f"{control} {k}")


@pytest.mark.parametrize("kind", ["sinusoid", "hold", "staircase"])
def test_batched_waveforms_equal_per_episode(kind):
    """The controls of a batch are one array expression for sinusoid/hold (32k episodes on the GPU path):
    bit for bit the per-episode waveforms; other kinds go episode by episode."""
    from simulate.protocols.indenter import (
        target_waveform,
        target_waveforms,
        xy_waveform,
        xy_waveforms,
    )

    extra = {"hold": ["protocol.kind=hold", "protocol.control=force"], "staircase": []}.get(kind, [])
    cfg = load_scene("fabric_1" if kind == "staircase" else "cnt_pdms", FAST + extra if kind != "staircase" else [])
    protos = [make_episode_protocol(cfg, s) for s in range(5)]
    assert {p.kind for p in protos} == {kind}
    t = np.linspace(-0.1, 3.0, 701)
    np.testing.assert_array_equal(target_waveforms(protos, cfg, t), np.stack([target_waveform(p, cfg, t) for p in protos]))
    np.testing.assert_array_equal(xy_waveforms(protos, cfg, t), np.stack([xy_waveform(p, cfg, t) for p in protos]))

"""press_stroke's taxel fields and ntype's element loads on the device (the GPU path, session 10) against their
numpy references: `press_stroke._load_batch` (numpy) vs `press_fields_warp`, `NtypeSensor.loads` (numpy einsums)
vs `ntype_loads_warp`. The fields are the same float64 values but for each indenter's footprint sum (taxel order
on the device, numpy's pairwise order on the host): ~1e-15 relative; the per-frame totals are bit for bit. The
electrode forces, rounded to float32 for the element chain, can then differ by 1 ulp, and the chain's float32
sums with cancellation (compliance x force) carry that as ~1 float32 epsilon of the channel's scale: the
recorded outputs agree within 2 ulp of the value or 8 float32 epsilons (~1e-6) of the channel's largest value
(the H100: displacement 3.6e-12 m apart at a scale of ~1e-5 m, where 2 ulp alone failed), and the measured
resistance, quantised to resolution_ohm, within one quantum where a reading sits on a rounding boundary."""

import numpy as np
import pytest

from scenes import load_scene
from simulate.contact import press_stroke
from simulate.generation.run import episode_protocols


def _inputs(cfg, E: int, T: int, seed: int = 0):
    """Indenter states that cover the cases: inside the pad, across its edge, fully off it, not touching."""
    rng = np.random.default_rng(seed)
    C = cfg.indenter.count
    half = cfg.pad.size_x_m / 2
    xy = rng.uniform(-1.1 * half, 1.1 * half, (E, T, C, 2))
    xy[:, 0, 0] = (half, -half)  # centred on the edge
    xy[:, 1, 0] = (2 * half, 0.0)  # off the pad (the others on it)
    xy[:, 1, 1:] *= 0.8
    z = rng.uniform(-3e-5, 1e-5, (E, T, C))  # some above the pad (no penetration)
    z[:, :2, 0] = -1e-5  # the edge and off-pad ones pressing
    pos = np.concatenate([xy, z[..., None]], -1)
    fn = np.where(z < 0, rng.uniform(0.0, 4.8, (E, T, C)), 0.0)
    ft = rng.uniform(-2.0, 2.0, (E, T, C, 2)) * (z < 0)[..., None]
    return pos, fn, ft, (z < 0).astype(float)


def _check_batches(host, dev, E: int, T: int) -> None:
    for name, ref in (("deformation_m", host.deformation_m), ("pressure_pa", host.pressure_pa), ("shear_pa", host.shear_pa)):
        got = getattr(dev, name).numpy().reshape(ref.shape)
        scale = np.abs(ref).max()
        assert scale > 0, name
        np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-14 * scale, err_msg=name)
        assert ((got == 0) == (ref == 0)).all(), name  # the same cells loaded
    for name in ("contact_force_n", "contact_points", "indenter_pos_m", "target", "time_s"):
        np.testing.assert_array_equal(getattr(dev, name), getattr(host, name), err_msg=name)


def _check_sensor(cfg, host, dev, seeds, device: str) -> None:
    from sensors.registry import make_sensor

    a = make_sensor(cfg, "warp", "cpu").run_load(host, seeds)
    b = make_sensor(cfg, "warp", device).run_load(dev, seeds)
    eps32 = float(np.finfo(np.float32).eps)
    for k in a:
        assert a[k].dtype == b[k].dtype == np.float32, k
        ref = a[k].astype(np.float64)
        assert np.abs(ref).max() > 0, k
        diff = np.abs(b[k].astype(np.float64) - ref)
        tol = np.maximum(2 * np.spacing(np.abs(a[k])).astype(np.float64), 8 * eps32 * np.abs(ref).max())
        if k == "resistance_measured":  # quantised: a reading on a rounding boundary may go one quantum either way
            q = cfg.sensor.readout.resolution_ohm
            assert (diff <= tol + q).all() and (diff > tol).mean() < 1e-2, (k, diff.max(), (diff > tol).mean())
            continue
        assert (diff <= tol).all(), (k, diff.max(), np.abs(ref).max())


def test_press_fields_kernel_matches_numpy_reference():
    cfg = load_scene("ntype")
    E, T = 6, 5
    pos, fn, ft, found = _inputs(cfg, E, T)
    protos = episode_protocols(cfg, list(range(E)), list(range(E)))
    host = press_stroke._load_batch(cfg, protos, pos, fn, ft, found)
    dev = press_stroke._load_batch(cfg, protos, pos, fn, ft, found, device_fields="cpu")
    assert not host.fields_on_device and dev.fields_on_device
    np.testing.assert_allclose(host.contact_force_n[:, 1, 2], fn[:, 1, 1:].sum(-1))  # the indenter off the pad dropped
    _check_batches(host, dev, E, T)
    _check_sensor(cfg, host, dev, list(range(E)), "cpu")


def test_sphere_indenters_keep_the_numpy_field():
    cfg = load_scene("ntype", ["indenter.shape=sphere", "indenter.radius_m=0.004"])
    pos, fn, ft, found = _inputs(cfg, 2, 3)
    protos = episode_protocols(cfg, [0, 1], [0, 1])
    b = press_stroke._load_batch(cfg, protos, pos, fn, ft, found, device_fields="cpu")
    assert not b.fields_on_device


@pytest.mark.gpu
def test_press_stroke_gpu_path_equals_host_path(gpu_device, monkeypatch):
    """MuJoCo Warp on the device under test, its sensordata through both paths: fields and sensor chain on the
    device (what the CLI runs there) against the numpy field and the chain on the CPU."""
    from simulate.contact.mujoco_warp import available

    if not available():
        pytest.skip("mujoco_warp not installed (extra: gpu)")
    dev = "cpu" if gpu_device == "cpu" else "cuda"
    cfg = load_scene("ntype", ["generation.physics=mujoco_warp", f"generation.device={dev}"])
    E = 4 if gpu_device == "cpu" else 64
    protos = episode_protocols(cfg, list(range(E)), list(range(E)))
    seen = []
    real = press_stroke._load_batch

    def spy(cfg_, protos_, pos, fn, ft, found, device_fields=None):
        seen.append((protos_, pos.copy(), fn.copy(), ft.copy(), found.copy()))
        return real(cfg_, protos_, pos, fn, ft, found, device_fields)

    monkeypatch.setattr(press_stroke, "_load_batch", spy)
    got = list(press_stroke.iter_press_stroke(cfg, protos, slice_episodes=E // 2, device_fields=gpu_device))
    assert [sl for sl, _ in got] == [slice(0, E // 2), slice(E // 2, E)] and len(seen) == 2
    for (sl, b), (p, pos, fn, ft, found) in zip(got, seen):
        assert b.fields_on_device
        host = real(cfg, p, pos, fn, ft, found)
        assert host.pressure_pa.max() > 0
        _check_batches(host, b, len(p), pos.shape[1])
        _check_sensor(cfg, host, b, list(range(sl.start, sl.stop)), gpu_device)

"""load_batch's host passes over a large batch's sensordata, split over threads (simulate.contact.load_field:
_columns): the same pose, position, force and contact count, bit for bit, split over threads as in one pass."""

import numpy as np

from scenes import load_scene
from simulate.contact import load_field as lf


def test_threaded_host_passes_equal_the_one_thread_expressions(monkeypatch):
    cfg = load_scene("cnt_pdms", ["pad.taxels_x=3", "pad.taxels_y=2", "generation.physics=mujoco"])
    rng = np.random.default_rng(4)
    E, T = 37, 11
    sens = rng.normal(0.0, 1e-3, (E, T, 20))
    sens[..., lf._FOUND] = rng.integers(0, 4, (E, T))
    sens[0, 0, lf._FORCE] = [0.0, -0.0, 0.0]  # signed zeros keep their sign through the negation
    sens = sens[:, :, :]  # a view, as the feed's shared block
    target = rng.normal(size=(E, T))
    monkeypatch.setattr(lf, "HOST_PASS_MIN_BYTES", 1 << 62)
    one = lf.load_batch(cfg, sens, target)
    monkeypatch.setattr(lf, "HOST_PASS_MIN_BYTES", 0)
    monkeypatch.setattr(lf, "HOST_PASS_THREADS", 3)
    monkeypatch.setattr(lf, "_HOST_PASSES", None)
    many = lf.load_batch(cfg, sens, target)
    assert lf._HOST_PASSES is not None  # the threaded path ran
    for name in ("indenter_pos_m", "contact_force_n", "contact_points", "deformation_m", "pressure_pa", "shear_pa"):
        a, b = getattr(one, name), getattr(many, name)
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), name
    assert float(np.abs(one.pressure_pa).max()) > 0.0  # the field saw the pressed frames
    assert np.signbit(many.contact_force_n[0, 0, 2])  # -(+0.0)


def test_threaded_float32_cast_equals_astype(monkeypatch):
    """The recorded load channels' cast to float32 (`as_float32`, split over threads for a large slice) gives
    astype's values bit for bit, for a strided view too; a float32 array comes back as it is."""
    rng = np.random.default_rng(5)
    a = rng.normal(0.0, 1e3, (29, 13, 6))[:, ::2, 1:4]  # a strided view, as a column of the sensordata
    a[0, 0, 0], a[1, 1, 1] = np.nan, -np.inf
    monkeypatch.setattr(lf, "HOST_PASS_MIN_BYTES", 0)
    monkeypatch.setattr(lf, "HOST_PASS_THREADS", 3)
    monkeypatch.setattr(lf, "_HOST_PASSES", None)
    got, ref = lf.as_float32(a), a.astype(np.float32)
    assert lf._HOST_PASSES is not None
    assert got.dtype == np.float32 and got.shape == ref.shape and got.tobytes() == ref.tobytes()
    f = ref.copy()
    assert lf.as_float32(f) is f

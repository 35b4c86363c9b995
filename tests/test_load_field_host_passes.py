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

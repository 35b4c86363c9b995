"""Fixtures shared by the rendering tests (tests/test_viz*.py)."""

import pytest


@pytest.fixture(scope="module")
def views(recs):
    """Episode 0 of each recording of the module's `recs` fixture, loaded as per-taxel fields."""
    from sensors.recording import Recording
    from simulate.fields import load_episode

    out = {}
    for key, path in recs.items():
        with Recording(path) as rec:
            out[key] = load_episode(rec, 0)
    return out


@pytest.fixture(scope="module")
def offscreen():
    """Skip (with the reason) where rendering cannot work; else return the render module."""
    try:
        from simulate import render

        pv = render.import_pyvista()
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"pyvista unavailable: {exc}")
    try:
        pl = pv.Plotter(off_screen=True, window_size=[32, 32])
        pl.add_mesh(pv.Sphere())
        img = pl.screenshot(return_img=True)
        pl.close()
        assert img is not None and img.size
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no offscreen OpenGL here (install libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1): {exc}")
    return render

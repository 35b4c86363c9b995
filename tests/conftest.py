"""Fixtures shared by several test files: the rendering tests (tests/test_viz*.py) and the device under test
of the gpu-marked tests (tests/test_gpu*.py)."""

import os

import pytest

GPU_DEVICE_ENV = "PIEZOTWIN_TEST_GPU_DEVICE"


@pytest.fixture(scope="session")
def gpu_device() -> str:
    """The Warp device the gpu-marked tests compare against "cpu": $PIEZOTWIN_TEST_GPU_DEVICE, default "cuda:0".

    A CUDA device is skipped (with the reason) where Warp sees none. "cpu" is never skipped: the same
    comparisons then run cpu against cpu, which checks the test logic on a machine without a GPU
    (PIEZOTWIN_TEST_GPU_DEVICE=cpu pytest -m gpu)."""
    from sensors.warp_setup import init_warp, resolve_device

    dev = os.environ.get(GPU_DEVICE_ENV, "cuda:0").strip() or "cuda:0"
    if dev == "cpu":
        return dev
    init_warp()
    import warp as wp

    if not dev.startswith("cuda"):
        pytest.fail(f"{GPU_DEVICE_ENV}={dev!r}: use cpu, cuda or cuda:N")
    if wp.get_cuda_device_count() == 0:
        pytest.skip(f"no CUDA device ({GPU_DEVICE_ENV}={dev}; set it to cpu to check the test logic here)")
    return resolve_device(dev)


@pytest.fixture(scope="module")
def views(recs):
    """Episode 0 of each recording of the module's `recs` fixture, loaded as per-taxel fields."""
    from sensors.data.recording import Recording
    from simulate.pictures.fields import load_episode

    out = {}
    for key, path in recs.items():
        with Recording(path) as rec:
            out[key] = load_episode(rec, 0)
    return out


@pytest.fixture(scope="module")
def offscreen():
    """Skip (with the reason) where rendering cannot work; else return the render module."""
    try:
        from simulate.pictures import render

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

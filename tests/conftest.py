"""Fixtures shared by several test files: the rendering tests (tests/test_viz*.py) and the device under test
of the gpu-marked tests (tests/test_gpu*.py); the hypothesis profiles of the fuzz tests."""

import os

import pytest
from hypothesis import settings

GPU_DEVICE_ENV = "PIEZOTWIN_TEST_GPU_DEVICE"
HYPOTHESIS_PROFILE_ENV = "PIEZOTWIN_HYPOTHESIS_PROFILE"

# Hypothesis profiles, loaded here (before the test modules are imported, so their settings inherit them):
# "default": derandomized (the examples are a fixed function of each test) and no example database, so the
#            default run is deterministic: it passes or fails the same way on every machine and every run;
# "fuzz":    randomized, 20x the examples (PIEZOTWIN_HYPOTHESIS_PROFILE=fuzz pytest tests/test_serial_codec.py);
#            a failure prints the @reproduce_failure blob that replays it.
# The slow-marked fuzz tests (pytest -m slow) are randomized with many examples whatever the profile.
settings.register_profile("default", derandomize=True, database=None, max_examples=150, deadline=None,
                          print_blob=True)
settings.register_profile("fuzz", derandomize=False, database=None, max_examples=3000, deadline=None,
                          print_blob=True)
settings.load_profile(os.environ.get(HYPOTHESIS_PROFILE_ENV, "default"))

# The commands' output as a user sees it piped to a file: pytest-xdist sets COLUMNS=80 in its worker processes, which
# the CLI's console would rightly honour (a user's COLUMNS wins); the tests of what the CLI prints read the piped width
os.environ.pop("COLUMNS", None)
# One test process per core (`pytest -n auto`): each one's torch / BLAS on one thread, so that two processes on two
# cores do not run four threads (set before torch is imported; a value the caller set wins)
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(_var, "1")


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

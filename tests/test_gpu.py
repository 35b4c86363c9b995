"""CUDA vs CPU equivalence of the cnt_pdms Warp chain (run on a GPU machine: pytest -m gpu). Skipped without
CUDA; the device under test is the `gpu_device` fixture (tests/conftest.py: $PIEZOTWIN_TEST_GPU_DEVICE,
default cuda:0; "cpu" checks the test logic cpu vs cpu). The other families: tests/test_gpu_families.py."""

import numpy as np
import pytest

from scenes import load_scene
from sensors.cnt_pdms.model import CntPdmsSensor
from sensors.cnt_pdms.params import MODE_DISPLACEMENT, MODE_FORCE, taxel_params
from sensors.cnt_pdms.kernels import TaxelChainWarp

pytestmark = pytest.mark.gpu


def test_taxel_kernel_cuda_equals_cpu(gpu_device):
    cfg = load_scene("cnt_pdms")
    tp = taxel_params(cfg)
    rng = np.random.default_rng(0)
    drive = rng.uniform(0, 0.04, (8, 500, 300)).astype(np.float32)
    for mode, scale in ((MODE_DISPLACEMENT, 1.0), (MODE_FORCE, 2e6)):
        a = TaxelChainWarp(tp, 8, 300, "cpu").run(drive * scale, mode)
        b = TaxelChainWarp(tp, 8, 300, gpu_device).run(drive * scale, mode)
        for x, y in zip(a, b):
            # same float32 equations; on CUDA the step's divisions and exp are the approximate instructions
            # (kernels.APPROX_MATH: __fdividef / __expf, 2 ulp and more for exp) and FMAs are contracted
            np.testing.assert_allclose(y, x, rtol=1e-5, atol=1e-7 * float(np.abs(x).max()))


def test_full_chain_cuda_equals_cpu(gpu_device):
    cfg = load_scene("cnt_pdms")
    t = np.arange(600) / 100.0
    d = (0.03 * (1 - np.cos(2 * np.pi * 1.0 * t)) / 2).astype(np.float32)
    mask = (np.random.default_rng(1).uniform(size=cfg.pad.n_taxels) < 0.1).astype(np.float32)
    drive = np.stack([d[:, None] * mask, 0.5 * d[:, None] * mask])
    a = CntPdmsSensor(cfg, device="cpu").run(drive, [1, 2])
    b = CntPdmsSensor(cfg, device=gpu_device).run(drive, [1, 2])
    for k in ("strain", "force", "resistance", "voltage", "resistance_measured"):
        np.testing.assert_allclose(b[k], a[k], rtol=1e-5, atol=1e-6 * float(np.abs(a[k]).max()), err_msg=k)
    assert np.abs(b["adc"].astype(int) - a["adc"].astype(int)).max() <= 1
    # deterministic on the GPU: no atomics, the block reduction sums in a fixed order
    c1 = CntPdmsSensor(cfg, device=gpu_device).run(drive, [1, 2])
    c2 = CntPdmsSensor(cfg, device=gpu_device).run(drive, [1, 2])
    for k in c1:
        np.testing.assert_array_equal(c1[k], c2[k])


def test_fused_pad_sum_cuda(gpu_device):
    """The pad's channel sum fused into the taxel kernel on the device (warp partial sums; 300 taxels = 9.4 warps,
    so padding lanes too) against the plain kernel + per-row sum on the CPU: strain and stress as the kernel test,
    conductance and force within float64 rounding of their sums; deterministic run to run."""
    import warp as wp

    from sensors import electronics as el

    cfg = load_scene("cnt_pdms")
    tp = taxel_params(cfg)
    E, T, N = 4, 400, 300
    drive = np.random.default_rng(2).uniform(0, 0.04, (E, T, N)).astype(np.float32)
    dc = wp.array(drive.reshape(-1), dtype=wp.float32, device="cpu")
    s, st, c = TaxelChainWarp(tp, E, N, "cpu").run_device(dc, T, MODE_DISPLACEMENT)
    g, f = (x.numpy() for x in el.sum_channels_warp(c, st, np.zeros(N, np.int32), 1, tp.taxel_area_m2, (E, T, N), "cpu"))
    dg = wp.array(drive.reshape(-1), dtype=wp.float32, device=gpu_device)
    runs = [TaxelChainWarp(tp, E, N, gpu_device).run_pad_device(dg, T, MODE_DISPLACEMENT, tp.taxel_area_m2) for _ in range(2)]
    s2, st2, g2, f2 = (x.numpy() for x in runs[0])
    for a, b in ((s.numpy(), s2), (st.numpy(), st2)):
        np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-7 * float(np.abs(a).max()))
    np.testing.assert_allclose(g2, g, rtol=1e-5)
    np.testing.assert_allclose(f2, f, rtol=1e-5, atol=1e-7 * float(np.abs(f).max()))
    for x, y in zip(runs[0], runs[1]):
        np.testing.assert_array_equal(x.numpy(), y.numpy())
    # the sensor takes the fused path on CUDA for a record without per-taxel fields: same outputs as on the CPU
    cfg2 = load_scene("cnt_pdms", ["generation.record=[force,resistance,adc]"])
    d = drive[:2, :, : cfg2.pad.n_taxels]
    a = CntPdmsSensor(cfg2, device="cpu").run(d, [1, 2])
    b = CntPdmsSensor(cfg2, device=gpu_device).run(d, [1, 2])
    assert set(a) == set(b) == {"force", "resistance", "adc"}
    for k in ("force", "resistance"):
        np.testing.assert_allclose(b[k], a[k], rtol=1e-5, atol=1e-6 * float(np.abs(a[k]).max()), err_msg=k)
    assert np.abs(b["adc"].astype(int) - a["adc"].astype(int)).max() <= 1


def test_parallel_readout_cuda_equals_serial_cpu(gpu_device):
    """The time-parallel readout on the device (its default there) against the serial kernel on the cpu."""
    import warp as wp

    from sensors import electronics as el
    from sensors.cnt_pdms.params import electronics_params

    for mode in ("zero_phase", "causal"):
        ep = electronics_params(load_scene("cnt_pdms", [f"sensor.electronics.filter_mode={mode}"]))
        E, T, C = 16, 1000, 2
        g = np.full((E, T, C), 1.0 / (ep.bridge_resistance_ohm * 1.001)) * (1 + 0.01 * np.sin(np.arange(T) / 30.0))[None, :, None]
        noise = el.NoiseSeeds(list(range(100, 100 + E)), 3e-3, 5e-3)
        ref, st = el.readout_warp(wp.array(g.reshape(-1), dtype=wp.float64, device="cpu"), (E, T, C), noise, ep, None, "cpu")
        got, st_g = el.readout_warp(wp.array(g.reshape(-1), dtype=wp.float64, device=gpu_device), (E, T, C), noise, ep,
                                    None, gpu_device)
        d = got["adc"].astype(int) - ref["adc"].astype(int)
        assert np.abs(d).max() <= 1 and (d == 0).mean() > 0.999
        for k in ("resistance", "bridge_v"):
            np.testing.assert_allclose(got[k], ref[k], rtol=1e-12, err_msg=k)
        np.testing.assert_allclose(got["filtered_v"], ref["filtered_v"], rtol=0, atol=2 * ep.lsb_v)
        np.testing.assert_allclose(st_g.pink, st.pink, rtol=1e-9, atol=1e-9)


def test_reserved_staging_buffer_takes_the_copies(gpu_device):
    # the GPU feed page-locks a slice's staging buffers ahead (`reserve_staging`): the copies of that call site
    # then land in the reserved buffer (no new page-locking), a group's shorter last slice too, with their values
    import warp as wp

    from sensors import warp_setup as ws

    if not str(gpu_device).startswith("cuda"):
        pytest.skip("page-locked staging is for CUDA arrays")
    ws.release_staging()
    assert ws.reserve_staging({("test-reserve", 0): 8000}) >= 8000 and ws.reserve_staging({("test-reserve", 0): 400}) == 0
    reserved = ws._PINNED[("test-reserve", 0)]
    with ws.host_staging(), ws.staging_log() as log:
        full = ws.to_host(wp.array(np.arange(2000, dtype=np.float32), device=gpu_device), "test-reserve")
        np.testing.assert_array_equal(full, np.arange(2000, dtype=np.float32))
        short = ws.to_host(wp.array(np.arange(500, dtype=np.float64), device=gpu_device), "test-reserve")
        np.testing.assert_array_equal(short, np.arange(500, dtype=np.float64))
    assert ws._PINNED[("test-reserve", 0)] is reserved and log == {("test-reserve", 0): 8000}
    assert short.ctypes.data == full.ctypes.data == reserved.ptr
    ws.release_staging()


def test_release_staging_frees_the_pinned_buffers_and_keeps_views(gpu_device):
    # the GPU feed unpins its staging buffers while the writers finish: the buffers go, a view handed out before
    # keeps its values (it holds its buffer), and the next copy makes a new buffer
    import warp as wp

    from sensors import warp_setup as ws

    if not str(gpu_device).startswith("cuda"):
        pytest.skip("page-locked staging is for CUDA arrays")
    src = wp.array(np.arange(1000, dtype=np.float32), device=gpu_device)
    with ws.host_staging():
        view = ws.to_host(src, "test-release")
    assert ws.release_staging() >= 4000 and ws.release_staging() == 0
    np.testing.assert_array_equal(view, np.arange(1000, dtype=np.float32))
    with ws.host_staging():
        again = ws.to_host(src, "test-release")
    assert again is not view and ws.release_staging() >= 4000

"""The whole-pad channel sum fused into the cnt_pdms taxel kernel (TaxelChainWarp.run_device_pad, the CUDA path
of sensor.readout = pad) against the taxel kernel + the separate channel sum. On the CPU (one taxel per block)
the sums run in taxel order: bit for bit the same (and with 8 taxels per thread, as on CUDA, the float64 sums
of these float32 values come out the same too); CUDA: tests/test_gpu.py."""

import numpy as np
import pytest
import warp as wp

from scenes import load_scene
from sensors import electronics as el
from sensors.cnt_pdms.kernels import TaxelChainWarp
from sensors.cnt_pdms.params import MODE_DISPLACEMENT, MODE_FORCE, taxel_params


@pytest.mark.parametrize("mode,scale,per_thread", [(MODE_DISPLACEMENT, 1.0, None), (MODE_FORCE, 2e6, None),
                                                    (MODE_DISPLACEMENT, 1.0, 8)])
def test_fused_pad_sum_equals_separate_sum(mode, scale, per_thread):
    tp = taxel_params(load_scene("cnt_pdms"))
    E, T, N = 2, 150, 225
    drive = np.random.default_rng(mode).uniform(0, 0.04 * scale, (E, T, N)).astype(np.float32)
    d = wp.array(drive.reshape(-1), dtype=wp.float32, device="cpu")
    a = TaxelChainWarp(tp, E, N, "cpu")
    s, st, c = a.run_device(d, T, mode)
    g, f = el.sum_channels_warp(c, st, np.zeros(N, np.int32), 1, tp.taxel_area_m2, (E, T, N), "cpu")
    assert np.ptp(g.numpy()) > 0.1 * np.abs(g.numpy()).max()  # the drive moves the conductance
    b = TaxelChainWarp(tp, E, N, "cpu")
    outs, g2, f2 = b.run_device_pad(d, T, mode, tp.taxel_area_m2, write=(True, True, False),
                                       per_thread=per_thread)
    np.testing.assert_array_equal(g2.numpy(), g.numpy())
    np.testing.assert_array_equal(f2.numpy(), f.numpy())
    np.testing.assert_array_equal(outs[0].numpy(), s.numpy())
    np.testing.assert_array_equal(outs[1].numpy(), st.numpy())
    assert outs[2].shape[0] == 0  # the conductance is not written when not asked for
    for x, y in zip(vars(a.state()).values(), vars(b.state()).values()):
        np.testing.assert_array_equal(y, x)

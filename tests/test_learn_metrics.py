"""learn.metrics on hand-computed cases."""

import math

import numpy as np
import pytest

from learn import metrics as M

REF = [1.0, 2.0, 3.0, 4.0]
EST = [1.0, 2.0, 3.0, 5.0]


def test_point_metrics_by_hand():
    assert M.mae(REF, EST) == pytest.approx(0.25)
    assert M.mse(REF, EST) == pytest.approx(0.25)
    assert M.rmse(REF, EST) == pytest.approx(0.5)
    assert M.r2(REF, EST) == pytest.approx(1 - 1 / 5)  # SS_tot = 2.25 + 0.25 + 0.25 + 2.25
    assert M.pearson_r(REF, EST) == pytest.approx(6.5 / math.sqrt(5 * 8.75))
    assert M.mean_relative_error(REF, EST) == pytest.approx(0.25 / 4)  # only the last sample: |5-4|/4
    assert M.mean_relative_error([0.0, 2.0], [1.0, 3.0], min_abs_ref=0.0) == pytest.approx(0.5)  # F=0 left out
    assert M.r2(REF, REF) == 1.0 and M.pearson_r(REF, REF) == pytest.approx(1.0)
    assert math.isnan(M.r2([1, 1, 1], [1, 2, 3]))
    with pytest.raises(ValueError):
        M.mae([1, 2], [1, 2, 3])


def test_hysteresis_error_by_hand():
    drive = np.array([0.0, 1.0, 2.0, 1.0, 0.0])
    force = np.array([0.0, 1.0, 2.0, 1.0, 0.0])
    out = np.array([0.0, 1.0, 2.0, 0.5, 0.0])
    # loading F(y) = y; unloading F(0.5) = 1 -> largest gap 0.5 at y = 0.5, over F_max = 2 -> 25 %
    assert M.hysteresis_error_fso(force, out, drive, n_grid=201) == pytest.approx(25.0, abs=1e-9)
    assert M.hysteresis_error_fso(force, force, drive) == pytest.approx(0.0)  # perfect compensator


def test_cycles_and_per_cycle_hysteresis():
    d = np.array([0, 0, 1, 2, 1, 0, 0, 1, 0, 0], float)
    assert M.cycle_slices(d, min_len=2) == [slice(1, 6), slice(6, 9)]
    assert M.cycle_slices(d) == [slice(1, 6)]
    f = np.array([0.0, 1.0, 2.0, 1.0, 0.0])
    drive = np.concatenate([f, f[1:]])
    force = drive.copy()
    out = np.concatenate([[0.0, 1.0, 2.0, 0.5, 0.0], [1.0, 2.0, 1.0, 0.0]])
    h = M.loop_hysteresis(force, out, drive)
    assert len(h) == 2 and h[0] == pytest.approx(25.0, abs=0.2) and h[1] == pytest.approx(0.0)
    r = M.regression_metrics(REF, EST)
    assert set(r) == {"mae", "rmse", "r2", "mse", "r"}

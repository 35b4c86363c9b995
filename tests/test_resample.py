"""sensors/data/resample.py: a real recording onto a model's clock; dropped samples (NaN, as `piezotwin capture`
leaves them on a stream's missing samples) are bridged, a long gap is refused naming it."""

import math

import numpy as np
import pytest

from sensors.data.resample import MAX_GAP_S, resample


def _signal(n=3000, fs=143.0, seed=0):
    t = np.arange(n) / fs
    rng = np.random.default_rng(seed)
    return t, np.stack([np.sin(2 * np.pi * 0.3 * t) * 5 + 6, 1000 / (1 + t)], 1) + 0.01 * rng.standard_normal((n, 2))


def test_a_clean_signal_resamples_as_the_plain_average_bit_for_bit():
    """Without NaN the arithmetic is the causal moving average over one output period, then linear interpolation."""
    t, a = _signal()
    w = int(round(((len(t) - 1) / (t[-1] - t[0])) / 20.0))
    pad = np.concatenate([np.repeat(a[:1], w - 1, axis=0), a])
    avg = np.stack([np.convolve(pad[:, j], np.ones(w) / w, mode="valid") for j in range(2)], axis=1)
    tn = t[0] + np.arange(int(math.floor((t[-1] - t[0]) * 20.0)) + 1) / 20.0
    ref = np.stack([np.interp(tn, t, avg[:, j]) for j in range(2)], axis=1)
    tt, out = resample(t, a, 20.0)
    assert np.array_equal(tt, tn) and np.array_equal(out, ref)


def test_dropped_samples_are_left_out_of_the_average_and_bridged():
    """5 % of the samples dropped at random (and a 0.5 s stall): the result has no NaN and stays within the noise of
    the clean signal's; before, each NaN spread over a whole averaging window (24 % NaN at 20 Hz)."""
    t, a = _signal()
    rng = np.random.default_rng(1)
    holed = a.copy()
    holed[rng.random(len(t)) < 0.05] = np.nan
    holed[1000:1072] = np.nan  # a 0.5 s stall of the stream
    _, clean = resample(t, a, 20.0)
    _, out = resample(t, holed, 20.0)
    assert np.isfinite(out).all()
    assert np.max(np.abs(out - clean)[:, 0]) < 0.6 and np.median(np.abs(out - clean)[:, 0]) < 0.02


def test_a_gap_longer_than_the_bridge_is_refused_naming_it():
    t, a = _signal()
    a[500:500 + int(2.0 * 143)] = np.nan
    with pytest.raises(ValueError, match=r"no sample for 2\.0\d s from t = 3\.4\d s"):
        resample(t, a, 20.0)
    assert MAX_GAP_S < 2.0
    with pytest.raises(ValueError, match="no sample at all"):
        resample(t, np.full_like(a, np.nan), 20.0)


def test_an_episode_is_cut_at_a_long_stall_into_parts():
    """resample_parts: a 3 s stretch where one of the two signals has no sample cuts the episode in two parts, each
    resampled on its own; a part shorter than MIN_PART_S is left out; without such a stretch the one part is
    resample's own output."""
    from sensors.data.resample import MIN_PART_S, resample_parts

    t = np.arange(0, 20, 0.01)
    a, b = np.sin(t), np.cos(t)
    a2 = a.copy()
    a2[500:800] = np.nan  # 5-8 s
    a2[1850:1900] = np.nan  # a 0.5 s drop near the end: bridged
    parts = resample_parts(t, [a2, b], 20.0)
    assert [(round(p[0][0], 2), round(p[0][-1], 2)) for p in parts] == [(0.0, 4.95), (8.0, 19.95)]
    assert all(np.isfinite(x).all() for p in parts for x in p[1])
    short = a.copy()
    short[100:400] = np.nan  # the part before the stall is 1 s long: left out
    assert [round(p[0][0], 2) for p in resample_parts(t, [short, b], 20.0)] == [4.0] and MIN_PART_S > 1.0
    whole = resample_parts(t, [a, b], 20.0)
    assert len(whole) == 1 and np.array_equal(whole[0][1][0], resample(t, a, 20.0)[1])

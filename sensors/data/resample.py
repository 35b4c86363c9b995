"""Resampling a uniformly sampled signal to another rate (real recordings onto a model's clock)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MAX_GAP_S", "MIN_PART_S", "PART_SEP", "key_matches", "resample", "resample_parts"]

MAX_GAP_S = 1.0  # estimate: the longest stretch without a sample that is bridged (a serial stall, a few dropped lines);
# `piezotwin capture` leaves NaN where a stream had no sample on the common clock


def resample(t: np.ndarray, a: np.ndarray, rate_hz: float, max_gap_s: float = MAX_GAP_S) -> tuple[np.ndarray, np.ndarray]:
    """Signal a [T, ...] at times t (uniform) -> (t', a') at rate_hz: a moving average over one output
    period (anti-aliasing when going down), then linear interpolation onto t' = t0 + k / rate.

    NaN samples (a stream's dropped samples) are left out of the average, and the interpolation bridges what stays
    without a sample, up to ``max_gap_s``; a longer gap raises ValueError (when and how long). Without NaN the
    arithmetic is the plain average's, bit for bit."""
    t = np.asarray(t, np.float64)
    a = np.asarray(a, np.float64).reshape(len(t), -1)
    fs = (len(t) - 1) / (t[-1] - t[0])
    w = int(round(fs / rate_hz))
    finite = np.isfinite(a)
    clean = bool(finite.all())
    for j in range(a.shape[1] if not clean else 0):  # the stretches without a sample, on the input's own clock
        ok = finite[:, j]
        if not ok.any():
            raise ValueError("no sample at all (every value is NaN)")
        tt = np.concatenate([[t[0]], t[ok], [t[-1]]])
        gaps = np.diff(tt)
        g = int(np.argmax(gaps))
        if gaps[g] > max_gap_s + 1.5 / fs:
            raise ValueError(f"no sample for {gaps[g]:.2f} s from t = {tt[g] - t[0]:.2f} s (gaps up to {max_gap_s:g} s are "
                             "bridged); cut the episode there or re-capture")
    if w > 1:
        pad = np.concatenate([np.repeat(a[:1], w - 1, axis=0), a])  # causal: the average of the last period
        if clean:
            k = np.ones(w) / w
            a = np.stack([np.convolve(pad[:, j], k, mode="valid") for j in range(a.shape[1])], axis=1)
        else:
            ok = np.isfinite(pad)
            ones = np.ones(w)
            s = np.stack([np.convolve(np.where(ok[:, j], pad[:, j], 0.0), ones, mode="valid") for j in range(a.shape[1])], axis=1)
            c = np.stack([np.convolve(ok[:, j].astype(np.float64), ones, mode="valid") for j in range(a.shape[1])], axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                a = np.where(c > 0, s / c, np.nan)
    n = int(math.floor((t[-1] - t[0]) * rate_hz)) + 1
    tn = t[0] + np.arange(n) / rate_hz
    if clean:
        return tn, np.stack([np.interp(tn, t, a[:, j]) for j in range(a.shape[1])], axis=1)
    cols = []
    for j in range(a.shape[1]):
        ok = np.isfinite(a[:, j])
        cols.append(np.interp(tn, t[ok], a[ok, j]))
    return tn, np.stack(cols, axis=1)


MIN_PART_S = 2.0  # estimate: a stretch between two long gaps shorter than this holds no whole press; it is left out
PART_SEP = "@"  # an episode cut at its long gaps is read as parts EP@1, EP@2, ... (resample_parts)


def resample_parts(t: np.ndarray, arrays: list[np.ndarray], rate_hz: float, max_gap_s: float = MAX_GAP_S,
                   min_part_s: float = MIN_PART_S) -> list[tuple[np.ndarray, list[np.ndarray]]]:
    """The signals ``arrays`` (each [T, ...] on the times t) cut at every stretch of more than max_gap_s where any of
    them has no sample (a stalled stream), each part resampled (resample) on its own: [(t', [a'...]), ...].
    Parts shorter than min_part_s are left out; without such a stretch: one part, as resample gives it."""
    t = np.asarray(t, np.float64)
    ok = np.ones(len(t), bool)
    for a in arrays:
        ok &= np.isfinite(np.asarray(a, np.float64).reshape(len(t), -1)).all(axis=1)
    if not ok.any():
        raise ValueError("no sample at all (every value is NaN)")
    idx = np.flatnonzero(ok)
    cuts = np.flatnonzero(np.diff(t[idx]) > max_gap_s)  # a long stretch between two samples that have every value
    bounds = [(idx[0], idx[-1])] if not len(cuts) else \
        [(idx[0], idx[cuts[0]])] + [(idx[c + 1], idx[d]) for c, d in zip(cuts[:-1], cuts[1:])] + [(idx[cuts[-1] + 1], idx[-1])]
    parts = []
    for a0, b0 in bounds:
        if t[b0] - t[a0] < min_part_s:
            continue
        sl = slice(a0, b0 + 1)
        outs = [resample(t[sl], np.asarray(a)[sl], rate_hz, max_gap_s) for a in arrays]
        parts.append((outs[0][0], [o[1] for o in outs]))
    return parts


def key_matches(key: str, glob: str) -> bool:
    """A run key against a user's episode glob: the key itself, or for a part EP@k (resample_parts) its episode EP."""
    import fnmatch

    return fnmatch.fnmatch(key, glob) or (PART_SEP in key and fnmatch.fnmatch(key.rsplit(PART_SEP, 1)[0], glob))

"""Resampling a uniformly sampled signal to another rate (real recordings onto a model's clock)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["resample"]


def resample(t: np.ndarray, a: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Signal a [T, ...] at times t (uniform) -> (t', a') at rate_hz: a moving average over one output
    period (anti-aliasing when going down), then linear interpolation onto t' = t0 + k / rate."""
    t = np.asarray(t, np.float64)
    a = np.asarray(a, np.float64).reshape(len(t), -1)
    fs = (len(t) - 1) / (t[-1] - t[0])
    w = int(round(fs / rate_hz))
    if w > 1:
        k = np.ones(w) / w
        pad = np.concatenate([np.repeat(a[:1], w - 1, axis=0), a])  # causal: the average of the last period
        a = np.stack([np.convolve(pad[:, j], k, mode="valid") for j in range(a.shape[1])], axis=1)
    n = int(math.floor((t[-1] - t[0]) * rate_hz)) + 1
    tn = t[0] + np.arange(n) / rate_hz
    return tn, np.stack([np.interp(tn, t, a[:, j]) for j in range(a.shape[1])], axis=1)

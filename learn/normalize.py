"""Z-score normalisation (cnt_pdms eq. 10), statistics from the training set only, kept with the model."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class ZScore:
    mean: np.ndarray  # [n_features]
    std: np.ndarray  # [n_features], > 0

    @classmethod
    def fit(cls, arrays: Iterable[np.ndarray]) -> ZScore:
        a = np.concatenate([np.asarray(x, np.float64).reshape(len(x), -1) for x in arrays], axis=0)
        mean = a.mean(axis=0)
        std = a.std(axis=0)
        std = np.where(std > 1e-12 * np.maximum(1.0, np.abs(mean)), std, 1.0)  # constant feature: leave scale
        return cls(mean, std)

    @classmethod
    def identity(cls, n: int) -> ZScore:
        return cls(np.zeros(n), np.ones(n))

    def apply(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, np.float64) - self.mean) / self.std

    def invert(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(z, np.float64) * self.std + self.mean

    def to_json(self) -> dict[str, Any]:
        return {"mean": [float(v) for v in self.mean], "std": [float(v) for v in self.std]}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> ZScore:
        return cls(np.asarray(d["mean"], np.float64), np.asarray(d["std"], np.float64))

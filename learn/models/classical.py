"""Classical regressors as scikit-learn-style estimators, and the static compensators built on them.

``PolynomialRegression(degree)`` - least squares on [1, x, x^2, ..., x^degree] per input feature (no
cross terms), fitted from accumulated normal equations so that ``partial_fit`` adds data online and
``fit`` == reset + ``partial_fit``. Degree 1 is ordinary linear regression.

Compensators (static: the current sample only, as in the cnt_pdms paper's baselines):
  mean    predicts the training mean (the trivial baseline every model must beat)
  linear  cnt_pdms Table 3 "Linear regression"
  cubic   cnt_pdms Table 3 "Polynomial (3rd order)"
"""

from __future__ import annotations

from typing import Any

import numpy as np

from learn.models.base import Compensator, FnStreamer, Streamer, register

__all__ = ["CubicCompensator", "LinearCompensator", "MeanCompensator", "PolynomialRegression"]


class PolynomialRegression:
    """fit(X [N, F], y [N, O]) / partial_fit / predict(X) -> [N, O]; coef_ [O, 1 + F*degree]."""

    def __init__(self, degree: int = 1, ridge: float = 1e-10):
        if degree < 0:
            raise ValueError("degree must be >= 0")
        self.degree = int(degree)
        self.ridge = float(ridge)
        self._xtx: np.ndarray | None = None
        self._xty: np.ndarray | None = None
        self.n_samples_seen_ = 0
        self.coef_: np.ndarray | None = None

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {"degree": self.degree, "ridge": self.ridge}

    def set_params(self, **p: Any) -> PolynomialRegression:
        for k, v in p.items():
            setattr(self, k, v)
        return self

    def features(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, np.float64).reshape(len(X), -1)
        cols = [np.ones((len(X), 1))] + [X**k for k in range(1, self.degree + 1)]
        return np.concatenate(cols, axis=1)

    def partial_fit(self, X: np.ndarray, y: np.ndarray) -> PolynomialRegression:
        P = self.features(X)
        y = np.asarray(y, np.float64).reshape(len(P), -1)
        if self._xtx is None:
            self._xtx = np.zeros((P.shape[1], P.shape[1]))
            self._xty = np.zeros((P.shape[1], y.shape[1]))
        self._xtx += P.T @ P
        self._xty += P.T @ y
        self.n_samples_seen_ += len(P)
        self._solve()
        return self

    def fit(self, X: np.ndarray, y: np.ndarray) -> PolynomialRegression:
        self._xtx = self._xty = None
        self.n_samples_seen_ = 0
        return self.partial_fit(X, y)

    def _solve(self) -> None:
        a = self._xtx + self.ridge * max(1.0, np.trace(self._xtx)) * np.eye(len(self._xtx))
        self.coef_ = np.linalg.lstsq(a, self._xty, rcond=None)[0].T

    def predict(self, X: np.ndarray) -> np.ndarray:
        if self.coef_ is None:
            raise RuntimeError("PolynomialRegression: not fitted")
        return self.features(X) @ self.coef_.T


@register("mean")
class MeanCompensator(Compensator):
    """Predicts the training mean of the target, whatever the input."""

    def _fit(self, zx, zy, zv, *, seed, progress):
        return {}

    def _predict_z(self, z):
        return np.zeros((len(z), self.n_out))

    def _streamer(self) -> Streamer:
        return FnStreamer(self, lambda z: np.zeros(self.n_out))

    def state_tensors(self):
        return {"dummy": np.zeros(1)}

    def load_state_tensors(self, tensors):
        pass


class _PolyCompensator(Compensator):
    DEFAULTS = {"degree": 1, "ridge": 1e-10}

    def __init__(self, **hp: Any):
        super().__init__(**hp)
        self.est = PolynomialRegression(self.hparams["degree"], self.hparams["ridge"])

    def _fit(self, zx, zy, zv, *, seed, progress):
        self.est.fit(np.concatenate(zx), np.concatenate(zy))
        return {"n_samples": self.est.n_samples_seen_}

    def partial_fit(self, x: np.ndarray, y: np.ndarray) -> _PolyCompensator:
        """Online update with more (physical-unit) data; the normalisation stays that of the first fit."""
        self._check_fitted()
        self.est.partial_fit(self.x_norm.apply(np.asarray(x).reshape(len(x), -1)),
                             self.y_norm.apply(np.asarray(y).reshape(len(y), -1)))
        return self

    def _predict_z(self, z):
        return self.est.predict(z)

    def _streamer(self) -> Streamer:
        c, d = self.est.coef_, self.est.degree

        def f(z: np.ndarray) -> np.ndarray:
            p = np.concatenate([[1.0]] + [z**k for k in range(1, d + 1)])
            return c @ p

        return FnStreamer(self, f)

    def state_tensors(self):
        return {"coef": self.est.coef_, "xtx": self.est._xtx, "xty": self.est._xty,
                "n_samples_seen": np.asarray([self.est.n_samples_seen_], np.int64)}

    def load_state_tensors(self, t):
        self.est.coef_ = np.asarray(t["coef"], np.float64)
        self.est._xtx = np.asarray(t["xtx"], np.float64)
        self.est._xty = np.asarray(t["xty"], np.float64)
        self.est.n_samples_seen_ = int(t["n_samples_seen"][0])


@register("linear")
class LinearCompensator(_PolyCompensator):
    DEFAULTS = {"degree": 1, "ridge": 1e-10}


@register("cubic")
class CubicCompensator(_PolyCompensator):
    DEFAULTS = {"degree": 3, "ridge": 1e-10}

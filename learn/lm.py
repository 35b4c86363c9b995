"""Levenberg-Marquardt least squares (Levenberg 1944, Marquardt 1963), as MATLAB's ``trainlm`` runs it.

Minimise E(theta) = sum_i r_i(theta)^2 with residuals r = y - f(theta) and J = d f / d theta [N, P].
One step solves the damped normal equations

    (J^T J + mu I) delta = J^T r ,   theta_new = theta + delta

mu -> 0 gives the Gauss-Newton step (the normal-equations solution of the linearised problem); a large mu
gives delta ~ J^T r / mu = -(1/(2 mu)) grad E, a short gradient-descent step. Damping adaptation (trainlm):
a step that lowers E is accepted and mu is multiplied by ``mu_dec`` (0.1); a step that does not is rejected
and mu is multiplied by ``mu_inc`` (10) and the step re-solved with the same J, until one is accepted or
mu exceeds ``mu_max`` (1e10, training stops). Training also stops at ``max_epochs``, when E <= ``goal``,
when |grad| = |2 J^T r| < ``min_grad``, or after ``max_fail`` consecutive epochs without a validation
improvement (trainlm's "validation checks", 6); the weights of the best validation epoch are returned.

The solver is generic: ``residuals(theta) -> r [N]`` and ``jacobian(theta) -> J [N, P]`` (of f, i.e. of
-r) are callables on float64 numpy vectors; learn.models.bpnet supplies them for its network.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = ["LMConfig", "LMHistory", "LevenbergMarquardt", "lm_delta"]


@dataclass
class LMConfig:
    mu: float = 1e-3  # trainlm defaults
    mu_dec: float = 0.1
    mu_inc: float = 10.0
    mu_max: float = 1e10
    max_epochs: int = 1000
    goal: float = 0.0
    min_grad: float = 1e-7
    max_fail: int = 6

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class LMHistory:
    sse: list[float] = field(default_factory=list)  # training sum of squared residuals after each epoch
    valid_sse: list[float] = field(default_factory=list)
    mu: list[float] = field(default_factory=list)  # damping after each epoch
    grad_norm: list[float] = field(default_factory=list)
    rejected: list[int] = field(default_factory=list)  # rejected trial steps in each epoch
    best_epoch: int = -1
    stop_reason: str = ""

    @property
    def epochs(self) -> int:
        return len(self.sse)

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "epochs": self.epochs}


def lm_delta(J: np.ndarray, r: np.ndarray, mu: float) -> np.ndarray:
    """The LM step: solve (J^T J + mu I) delta = J^T r (Cholesky; least squares if J^T J is singular
    and mu = 0)."""
    J = np.asarray(J, np.float64)
    r = np.asarray(r, np.float64).ravel()
    A = J.T @ J + float(mu) * np.eye(J.shape[1])
    g = J.T @ r
    try:
        c = np.linalg.cholesky(A)
        return np.linalg.solve(c.T, np.linalg.solve(c, g))
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(A, g, rcond=None)[0]


class LevenbergMarquardt:
    """trainlm's outer loop: ``step`` is one epoch (one Jacobian, trial steps until one is accepted),
    ``fit`` runs epochs with the stopping rules of the module docstring."""

    def __init__(self, residuals: Callable[[np.ndarray], np.ndarray], jacobian: Callable[[np.ndarray], np.ndarray],
                 cfg: LMConfig | None = None):
        self.residuals, self.jacobian = residuals, jacobian
        self.cfg = cfg or LMConfig()
        self.mu = float(self.cfg.mu)

    def step(self, theta: np.ndarray, r: np.ndarray | None = None, J: np.ndarray | None = None
             ) -> tuple[np.ndarray, float, bool, int]:
        """One epoch from theta (its residuals r and Jacobian J if already computed): returns (theta', sse',
        accepted, rejected trials). On failure (mu past mu_max) theta is returned unchanged, accepted False."""
        c = self.cfg
        r = self.residuals(theta) if r is None else r
        sse = float(r @ r)
        J = self.jacobian(theta) if J is None else J
        rejected = 0
        while True:
            delta = lm_delta(J, r, self.mu)
            cand = theta + delta
            rc = self.residuals(cand)
            e = float(rc @ rc)
            if np.isfinite(e) and e < sse:
                self.mu = max(self.mu * c.mu_dec, 1e-20)
                return cand, e, True, rejected
            rejected += 1
            self.mu *= c.mu_inc
            if self.mu > c.mu_max:
                return theta, sse, False, rejected

    def fit(self, theta0: np.ndarray, valid: Callable[[np.ndarray], float] | None = None,
            callback: Callable[[int, LMHistory], None] | None = None) -> tuple[np.ndarray, LMHistory]:
        """Train from theta0; ``valid(theta) -> validation SSE`` drives early stopping (else training SSE)."""
        c = self.cfg
        theta = np.asarray(theta0, np.float64).copy()
        h = LMHistory()
        r = self.residuals(theta)
        sse = float(r @ r)
        best_theta, best_v = theta.copy(), (valid(theta) if valid else sse)
        fails = 0
        h.stop_reason = "max_epochs"
        for epoch in range(c.max_epochs):
            r, J = self.residuals(theta), self.jacobian(theta)
            gn = float(np.linalg.norm(2.0 * J.T @ r))  # |grad E| (E = sum r^2; J is d f / d theta = -d r / d theta)
            if gn < c.min_grad:
                h.stop_reason = "min_grad"
                break
            theta, sse, ok, rej = self.step(theta, r, J)
            v = valid(theta) if valid else sse
            h.sse.append(sse), h.valid_sse.append(v), h.mu.append(self.mu), h.grad_norm.append(gn), h.rejected.append(rej)
            if callback:
                callback(epoch, h)
            if v < best_v:
                best_v, best_theta, fails, h.best_epoch = v, theta.copy(), 0, epoch
            else:
                fails += 1
            if not ok:
                h.stop_reason = "mu_max"
                break
            if sse <= c.goal:
                h.stop_reason = "goal"
                break
            if valid is not None and fails >= c.max_fail:
                h.stop_reason = "validation_checks"
                break
        return best_theta, h

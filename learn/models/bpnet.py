"""The fabric paper's BP network, trained by Levenberg-Marquardt (learn.lm), as a compensator.

Paper (fabric, sect. 4): inputs the current and the previous resistance (R_t, R_{t-1}), two hidden layers of
five sigmoid neurons, a linear output (the static resistance R_estimated), trained with the Levenberg-
Marquardt algorithm (MATLAB trainlm: mu 1e-3, x0.1 / x10, validation checks 6). Ours:

    a1 = sigmoid(W1 [R_t, R_{t-1}] + b1)      5 units
    a2 = sigmoid(W2 a1 + b2)                   5 units
    y  = w3 . a2 + b3                          linear

on z-scored inputs and target (the statistics live with the compensator, as for every model here; MATLAB
uses mapminmax to [-1, 1] instead). The Jacobian of the outputs with respect to all weights is computed in
closed form (backpropagation of d y / d a per sample), so one LM epoch is one forward pass, one Jacobian and
one P x P solve (P = 51 for 2-5-5-1). Initial weights: Nguyen-Widrow (MATLAB's initnw); the best of
``restarts`` seeded initialisations on the validation SSE is kept.

``lags``: previous samples besides the current one as inputs; 1 = the paper's (R_t, R_{t-1}).
``observations``: train on a random subset of this many (input, target) examples (the fabric paper's Appendix
Table 2 varies it); None = all.
Before the first sample the input is taken to have rested at its first value, as for every model here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from learn.lm import LevenbergMarquardt, LMConfig
from learn.models.base import Compensator, Streamer, edge_windows, register

__all__ = ["BPNet", "BPNetCompensator"]


def _sigmoid(a: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * a))  # = 1 / (1 + exp(-a)), without overflow


class BPNet:
    """A fully connected net n_in -> hidden... (sigmoid) -> 1 (linear) with its parameters in one flat vector
    (per layer: W row-major [out, in], then b) and its closed-form Jacobian."""

    def __init__(self, n_in: int, hidden: list[int]):
        self.sizes = [int(n_in), *[int(h) for h in hidden], 1]
        self.shapes = [(b, a) for a, b in zip(self.sizes[:-1], self.sizes[1:])]
        self.n_params = sum(o * i + o for o, i in self.shapes)

    def unpack(self, theta: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        out, k = [], 0
        for o, i in self.shapes:
            W = theta[k : k + o * i].reshape(o, i)
            k += o * i
            out.append((W, theta[k : k + o]))
            k += o
        return out

    def init(self, rng: np.random.Generator) -> np.ndarray:
        """Nguyen-Widrow for the hidden layers (inputs assumed in about [-1, 1] after z-scoring), uniform
        [-1, 1] scaled by 1/sqrt(fan-in) for the output layer."""
        parts = []
        for li, (o, i) in enumerate(self.shapes):
            if li < len(self.shapes) - 1:
                beta = 0.7 * o ** (1.0 / i)
                W = rng.uniform(-1, 1, (o, i))
                W *= beta / np.linalg.norm(W, axis=1, keepdims=True)
                b = rng.uniform(-beta, beta, o)
                W, b = 4.0 * W, 4.0 * b  # logistic sigmoid has slope 1/4 where tanh has 1
            else:
                W = rng.uniform(-1, 1, (o, i)) / np.sqrt(i)
                b = np.zeros(o)
            parts += [W.ravel(), b]
        return np.concatenate(parts)

    def forward(self, theta: np.ndarray, X: np.ndarray, keep: bool = False):
        acts = [np.asarray(X, np.float64)]
        layers = self.unpack(theta)
        for li, (W, b) in enumerate(layers):
            a = acts[-1] @ W.T + b
            acts.append(a if li == len(layers) - 1 else _sigmoid(a))
        return (acts[-1][:, 0], acts) if keep else acts[-1][:, 0]

    def jacobian(self, theta: np.ndarray, X: np.ndarray) -> np.ndarray:
        """d y_n / d theta, [N, P], by backpropagating d y / d (pre-activation) layer by layer."""
        _, acts = self.forward(theta, X, keep=True)
        layers = self.unpack(theta)
        N = len(X)
        blocks: list[np.ndarray] = []
        D = np.ones((N, 1))  # d y / d (pre-activation of the output layer)
        for li in range(len(layers) - 1, -1, -1):
            W, _ = layers[li]
            a_in = acts[li]
            blocks.append(D)  # bias
            blocks.append((D[:, :, None] * a_in[:, None, :]).reshape(N, -1))  # W [out, in] row-major
            if li > 0:
                h = acts[li]
                D = (D @ W) * h * (1.0 - h)
        return np.concatenate(blocks[::-1], axis=1)


@register("bp_lm")
class BPNetCompensator(Compensator):
    """fabric sect. 4: BP network (R_t, R_{t-1}) -> 5 sigmoid -> 5 sigmoid -> R_static, Levenberg-Marquardt."""

    DEFAULTS: dict[str, Any] = {"hidden": [5, 5], "lags": 1, "restarts": 3, "max_epochs": 1000, "max_fail": 6,
                                "mu": 1e-3, "mu_dec": 0.1, "mu_inc": 10.0, "mu_max": 1e10, "min_grad": 1e-7,
                                "observations": None}
    temporal = True

    @property
    def context(self) -> int:
        return int(self.hparams["lags"]) + 1

    def _net(self) -> BPNet:
        return BPNet(self.n_in * self.context, list(self.hparams["hidden"]))

    def _features(self, z: np.ndarray) -> np.ndarray:
        """[T, n_in] -> [T, n_in * context]: (x_t, x_{t-1}, ...) newest first, edge-padded."""
        W = edge_windows(np.asarray(z, np.float64), self.context)[:, ::-1, :]
        return W.reshape(len(z), -1)

    def lm_config(self) -> LMConfig:
        h = self.hparams
        return LMConfig(mu=h["mu"], mu_dec=h["mu_dec"], mu_inc=h["mu_inc"], mu_max=h["mu_max"],
                        max_epochs=int(h["max_epochs"]), min_grad=h["min_grad"], max_fail=int(h["max_fail"]))

    def _fit(self, zx, zy, zv, *, seed, progress):
        if self.n_out != 1:
            raise ValueError("bp_lm: one output only (the paper's static resistance)")
        X = np.concatenate([self._features(x) for x in zx])
        y = np.concatenate([v[:, 0] for v in zy])
        rng = np.random.default_rng(int(seed))
        idx = None
        if self.hparams["observations"] is not None:  # train on a random subset of n (input, target) examples
            idx = np.sort(rng.choice(len(y), size=min(int(self.hparams["observations"]), len(y)), replace=False))
            X, y = X[idx], y[idx]
        net = self._net()
        if zv is not None:
            Xv = np.concatenate([self._features(x) for x in zv[0]])
            yv = np.concatenate([v[:, 0] for v in zv[1]])
            valid = lambda th: float(np.sum((yv - net.forward(th, Xv)) ** 2))
        else:
            valid = None
        best = None
        runs = []
        for k in range(int(self.hparams["restarts"])):
            lm = LevenbergMarquardt(lambda th: y - net.forward(th, X), lambda th: net.jacobian(th, X), self.lm_config())
            theta, h = lm.fit(net.init(rng), valid=valid)
            score = valid(theta) if valid else float(np.sum((y - net.forward(theta, X)) ** 2))
            runs.append({"score_sse": score, "epochs": h.epochs, "best_epoch": h.best_epoch, "stop": h.stop_reason,
                         "final_mu": h.mu[-1] if h.mu else None})
            if best is None or score < best[0]:
                best = (score, theta, h)
        self.theta = best[1]
        h = best[2]
        return {"optimizer": "levenberg-marquardt", "n_parameters": net.n_params, "n_train_examples": len(y),
                "epochs": h.epochs, "best_epoch": h.best_epoch, "stop_reason": h.stop_reason, "restarts": runs,
                "train_loss": [v / len(y) for v in h.sse],
                "valid_loss": [v / max(1, len(yv)) for v in h.valid_sse] if valid else [],
                "mu": h.mu, "grad_norm": h.grad_norm, "rejected_steps": h.rejected,
                "observation_index": None if idx is None else idx.tolist()}

    def _predict_z(self, z):
        return self._net().forward(self.theta, self._features(z))[:, None]

    def _streamer(self) -> Streamer:
        return BPStreamer(self)

    def state_tensors(self):
        return {"theta": np.asarray(self.theta, np.float64)}

    def load_state_tensors(self, t):
        self.theta = np.asarray(t["theta"], np.float64)


class BPStreamer(Streamer):
    """Keeps the last ``lags`` normalised samples (the first sample repeated at start)."""

    def __init__(self, comp: BPNetCompensator):
        self.c, self.net = comp, comp._net()
        self.reset()

    def reset(self) -> None:
        self.hist: list[np.ndarray] | None = None

    def step(self, x: np.ndarray) -> np.ndarray:
        c = self.c
        z = (np.asarray(x, np.float64).reshape(-1) - c.x_norm.mean) / c.x_norm.std
        if self.hist is None:
            self.hist = [z] * c.context
        else:
            self.hist = [z, *self.hist[:-1]]
        y = self.net.forward(c.theta, np.concatenate(self.hist)[None])[0]
        return np.array([y]) * c.y_norm.std + c.y_norm.mean

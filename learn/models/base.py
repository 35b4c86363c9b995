"""The compensator interface every model implements, and the registry that names them.

A compensator maps what the instrument reports, a sequence ``x`` [T, n_in] in physical units, to the
ground truth ``y`` [T, n_out] (e.g. resistance -> force). Scikit-learn style: ``fit(xs, ys)`` on lists
of episodes (each [T, n]), ``predict(x)`` on one episode (or a list). Output t depends on inputs
<= t only (causal), through at most ``context`` samples; before the first sample the input is taken
to have rested at its first value (edge padding), so ``stream()`` - one sample at a time, state
carried - gives exactly ``predict`` on the same sequence.

Everything a checkpoint needs: ``kind`` (registry name), ``hparams`` (JSON), ``x_norm``/``y_norm``
(z-score statistics of the training set), channel names + units, and ``state_tensors()`` (name ->
numpy array, stored as safetensors). ``from_state`` rebuilds from those without pickle.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from collections.abc import Sequence as Seq
from typing import Any, ClassVar

import numpy as np

from learn.normalize import ZScore

__all__ = ["MODELS", "Compensator", "Streamer", "edge_windows", "make_model", "register"]

MODELS: dict[str, type[Compensator]] = {}

# the modules whose classes register themselves with @register; make_model imports them on first use
BUILTIN_MODULES = (
    "learn.models.classical",  # mean, linear, cubic
    "learn.models.neural",  # mlp, lstm, gru
    "learn.models.tcn",  # tcn (ours)
    "learn.models.velostat",  # bp (velostat paper)
    "learn.models.bpnet",  # bp_lm (fabric paper: Levenberg-Marquardt)
    "learn.models.rbf",  # rbf (ntype paper)
    "learn.models.map_cnn",  # map_cnn (ntype, ours)
    "learn.models.ensemble",  # ensemble of any registered model
)


def load_builtin_models() -> dict[str, type[Compensator]]:
    """Import every built-in model module (each registers its classes) and return MODELS."""
    import importlib

    for mod in BUILTIN_MODULES:
        importlib.import_module(mod)
    return MODELS


def register(kind: str) -> Callable[[type[Compensator]], type[Compensator]]:
    """Class decorator: make a compensator constructible by name (``make_model(kind, **hparams)``)."""

    def deco(cls: type[Compensator]) -> type[Compensator]:
        if kind in MODELS and MODELS[kind] is not cls:
            raise ValueError(f"model kind {kind!r} already registered by {MODELS[kind].__qualname__}")
        cls.kind = kind
        MODELS[kind] = cls
        return cls

    return deco


def make_model(kind: str, **hparams: Any) -> Compensator:
    if kind not in MODELS:
        load_builtin_models()
    if kind not in MODELS:
        raise ValueError(f"unknown model {kind!r}; known: {sorted(MODELS)}")
    return MODELS[kind](**hparams)


def edge_windows(z: np.ndarray, w: int) -> np.ndarray:
    """[T, F] -> [T, w, F]: window t holds samples t-w+1..t, the first sample repeated before t=0."""
    z = np.asarray(z)
    pad = np.concatenate([np.repeat(z[:1], w - 1, axis=0), z], axis=0)
    return np.lib.stride_tricks.sliding_window_view(pad, w, axis=0).transpose(0, 2, 1)


class Streamer(ABC):
    """One sample in, one estimate out, state carried between calls (reset() to start over)."""

    @abstractmethod
    def step(self, x: np.ndarray) -> np.ndarray:
        """x [n_in] physical units -> y [n_out] physical units."""

    @abstractmethod
    def reset(self) -> None: ...

    def run(self, x: np.ndarray) -> np.ndarray:
        return np.stack([self.step(v) for v in np.asarray(x)])


class Compensator(ABC):
    kind: ClassVar[str] = ""
    DEFAULTS: ClassVar[dict[str, Any]] = {}
    temporal: ClassVar[bool] = False  # uses history (True) or the current sample only

    def __init__(self, **hparams: Any):
        unknown = set(hparams) - set(self.DEFAULTS)
        if unknown:
            raise ValueError(f"{self.kind}: unknown hyper-parameters {sorted(unknown)}; allowed {sorted(self.DEFAULTS)}")
        self.hparams: dict[str, Any] = {**self.DEFAULTS, **hparams}
        self.x_norm: ZScore | None = None
        self.y_norm: ZScore | None = None
        self.inputs: list[str] = []
        self.targets: list[str] = []
        self.units: dict[str, str] = {}
        self.n_in = 0
        self.n_out = 0
        self.history: dict[str, Any] = {}
        self.seed = 0

    # ------------------------------------------------------------------ public API

    @property
    def context(self) -> int:
        """Samples of input each output depends on (1 = static)."""
        return 1

    def fit(self, xs: Seq[np.ndarray], ys: Seq[np.ndarray], valid: tuple[Seq[np.ndarray], Seq[np.ndarray]] | None = None,
            *, seed: int = 0, progress: bool = False, inputs: Seq[str] = (), targets: Seq[str] = (),
            units: dict[str, str] | None = None) -> Compensator:
        zx, zy, zv = self.fit_setup(xs, ys, valid, inputs=inputs, targets=targets, units=units)
        self.history = self._fit(zx, zy, zv, seed=seed, progress=progress) or {}
        self.seed = int(seed)
        return self

    def fit_setup(self, xs: Seq[np.ndarray], ys: Seq[np.ndarray], valid=None, *, inputs: Seq[str] = (),
                  targets: Seq[str] = (), units: dict[str, str] | None = None):
        """fit()'s first half: channel names, units and the z-score statistics of the training set; returns the
        normalised (training inputs, training targets, validation pair or None) that _fit trains on."""
        xs = [np.asarray(x, np.float64).reshape(len(x), -1) for x in xs]
        ys = [np.asarray(y, np.float64).reshape(len(y), -1) for y in ys]
        self.n_in, self.n_out = xs[0].shape[1], ys[0].shape[1]
        self.inputs = list(inputs) or [f"x{i}" for i in range(self.n_in)]
        self.targets = list(targets) or [f"y{i}" for i in range(self.n_out)]
        self.units = dict(units or {})
        self.x_norm, self.y_norm = ZScore.fit(xs), ZScore.fit(ys)
        zx = [self.x_norm.apply(x) for x in xs]
        zy = [self.y_norm.apply(y) for y in ys]
        zv = None
        if valid is not None and len(valid[0]):
            zv = ([self.x_norm.apply(np.asarray(x, np.float64).reshape(len(x), -1)) for x in valid[0]],
                  [self.y_norm.apply(np.asarray(y, np.float64).reshape(len(y), -1)) for y in valid[1]])
        return zx, zy, zv

    def predict(self, x):
        """One episode [T, n_in] -> [T, n_out] (or a list of episodes -> list)."""
        if isinstance(x, (list, tuple)):
            return [self.predict(v) for v in x]
        self._check_fitted()
        x = np.asarray(x, np.float64).reshape(len(x), -1)
        return self.y_norm.invert(self._predict_z(self.x_norm.apply(x)))

    def stream(self) -> Streamer:
        self._check_fitted()
        return self._streamer()

    # ------------------------------------------------------------------ to implement

    @abstractmethod
    def _fit(self, zx: list[np.ndarray], zy: list[np.ndarray], zv, *, seed: int, progress: bool) -> dict | None: ...

    @abstractmethod
    def _predict_z(self, z: np.ndarray) -> np.ndarray:
        """Normalised [T, n_in] -> normalised [T, n_out]."""

    @abstractmethod
    def _streamer(self) -> Streamer: ...

    @abstractmethod
    def state_tensors(self) -> dict[str, np.ndarray]: ...

    @abstractmethod
    def load_state_tensors(self, tensors: dict[str, np.ndarray]) -> None:
        """Rebuild the fitted state (n_in, n_out, norms already set)."""

    # ------------------------------------------------------------------ helpers

    def _check_fitted(self) -> None:
        if self.x_norm is None or self.y_norm is None:
            raise RuntimeError(f"{self.kind}: not fitted")

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "hparams": self.hparams, "context": self.context, "n_in": self.n_in, "n_out": self.n_out}

    def __repr__(self) -> str:
        hp = ", ".join(f"{k}={v!r}" for k, v in self.hparams.items())
        return f"{type(self).__name__}({hp})"


class FnStreamer(Streamer):
    """Stateless streamer for static compensators: y_t = f(x_t)."""

    def __init__(self, comp: Compensator, fz: Callable[[np.ndarray], np.ndarray]):
        self.comp, self.fz = comp, fz
        xn, yn = comp.x_norm, comp.y_norm
        self._xm, self._xs, self._ym, self._ys = xn.mean, xn.std, yn.mean, yn.std

    def reset(self) -> None:
        pass

    def step(self, x: np.ndarray) -> np.ndarray:
        z = (np.asarray(x, np.float64).reshape(-1) - self._xm) / self._xs
        return self.fz(z) * self._ys + self._ym

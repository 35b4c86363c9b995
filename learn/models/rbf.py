"""Radial basis function network of the ntype paper (Wang & Song 2021, sect. 3.1): k-means centres,
Gaussian hidden units of one spread, linear output weights by recursive least squares (RLS).

Scikit-learn-style estimators, numpy only:
  KMeans(n_clusters)              k-means++ seeding + Lloyd iterations (seeded; empty clusters re-seeded
                                  at the worst-fitted points)
  RecursiveLeastSquares(delta)    block RLS: after any sequence of partial_fit calls the weights equal the
                                  batch solution W = (H^T H + delta I)^-1 H^T Y (forgetting factor 1); with
                                  lam < 1, exponentially weighted least squares
  RBFNetwork(n_centres, spread)   fit = k-means centres + RLS from scratch; partial_fit = more RLS updates
                                  (centres fixed after the first call); predict
  sweep_predict(d2_train, ...)    RBFNetwork's fit + predict on fixed centres for a whole spread sweep, from one
                                  distance matrix, RLS in closed form (ridge_weights, Cholesky) and eq. 12
                                  (exact_weights): what the ntype experiment's Tables 1 / 3 run

Spread conventions (``kernel``), d = ||X - X_j|| in input units:
  "eq9"     the paper's eq. 9 as printed, phi = exp(-||X - X_j|| / (2 sigma_j^2)) with sigma_j "the spread
            width of the Gaussian function" (sect. 3.1): the norm is not squared, so a unit is 0.5 at
            d = 2 ln2 spread^2 (1.4 at spread 1, 68 at spread 7, 139 at spread 10 input units). The paper's
            own definition, so the ntype experiment's headline (learn/experiments/ntype.py).
  "matlab"  MATLAB newrb/newrbe (whose word "spread" the paper uses): phi = exp(-ln2 (d / spread)^2), 0.5 at
            d = spread (reads eq. 9's unsquared norm as a typesetting slip).
  "sigma"   the textbook Gaussian with the square restored, exp(-d^2 / (2 spread^2)) (0.5 at d = 1.18 spread).
Which one the paper ran it does not say beyond eq. 9 (it calls the unit "Gaussian" but prints an unsquared
norm); the experiment reports the sweep under all three.

Output-weight solvers (``solver``):
  "rls"     recursive least squares from P0 = I / delta (sect. 3.1: "k-means ... and recursive least square
            (RLS) method are used"): after all rows, the ridge solution (H^T H + delta I)^-1 H^T Y, plus a bias unit.
  "exact"   eqs. 10-12 as printed: one unit per training sample (N centres = the N training inputs), no bias,
            Phi w = d solved exactly, w = Phi^-1 d (eq. 12; MATLAB newrbe's design, which adds an output bias).
            Nothing bounds w: where Phi is ill-conditioned (wide units, close samples) the readout noise of the
            training targets' inputs is amplified into the weights (the condition number is what the ntype
            experiment reports beside it).

The spread is a distance in input units, so it only means something for a stated input scale: the ntype
experiment min-max maps resistances onto the paper's kOhm ranges (eq. 13: R_z -> [16, 25], R_x, R_y ->
[32, 50]) before the network sees them (learn/experiments/ntype.py). The registered compensator ``rbf``
does the same generically: each input feature min-max mapped onto [0, input_span] (training set).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from learn.models.base import Compensator, FnStreamer, Streamer, register

__all__ = ["KERNELS", "SOLVERS", "KMeans", "RBFCompensator", "RBFNetwork", "RecursiveLeastSquares", "exact_weights",
           "half_distance", "kernel_phi", "ridge_weights", "sq_dist", "sweep_predict"]


def sq_dist(a: np.ndarray, b: np.ndarray, aa: np.ndarray | None = None) -> np.ndarray:
    """[N, F], [K, F] -> [N, K] squared Euclidean distances (clipped at 0): ||a||^2 - 2 a.b + ||b||^2, built in
    place (bit for bit the same as the out-of-place expression: doubling is exact and x - y = x + (-y) in IEEE
    arithmetic). aa: (a * a).sum(1), when the caller reuses it over many b."""
    d = a @ b.T
    d *= -2.0
    d += ((a * a).sum(1) if aa is None else aa)[:, None]
    d += (b * b).sum(1)[None, :]
    return np.maximum(d, 0.0, out=d)


KERNELS = ("eq9", "matlab", "sigma")
SOLVERS = ("rls", "exact")


def kernel_gamma(kernel: str, spread: float) -> float:
    """The unit's rate: phi = exp(-gamma d) for "eq9" (gamma = 1 / 2 spread^2, eq. 9), exp(-gamma d^2) otherwise."""
    if kernel == "eq9":
        return 0.5 / spread**2
    return math.log(2.0) / spread**2 if kernel == "matlab" else 0.5 / spread**2


def kernel_phi(kernel: str, spread: float, d2: np.ndarray, d: np.ndarray | None = None,
               out: np.ndarray | None = None) -> np.ndarray:
    """Hidden-unit outputs from squared distances d2 under `kernel` (see the module docstring). d: sqrt(d2), when
    the caller reuses it over many spreads ("eq9" only; same bits). out: where to write them (no temporaries)."""
    g = kernel_gamma(kernel, spread)
    x = (np.sqrt(d2) if d is None else d) if kernel == "eq9" else d2
    out = np.multiply(x, -g, out=out)
    return np.exp(out, out=out)


def ridge_weights(H: np.ndarray, Y: np.ndarray, delta: float = 1e-3) -> np.ndarray:
    """Output weights of RLS with forgetting factor 1 started from P0 = I / delta, after all rows of H [N, K],
    in closed form: W = (H^T H + delta I)^-1 H^T Y (Haykin, Adaptive Filter Theory, ch. 10: RLS of lam = 1 is
    the exponentially unweighted, delta-regularised least squares), solved by Cholesky. Equal to
    ``RecursiveLeastSquares(delta).fit(H, Y).W`` within round-off (tests/test_learn_ntype.py), at K^3 / 3 +
    N K^2 flops instead of the block recursion's ~3 N K^2 + (N / block) K^3."""
    from scipy.linalg import cho_factor, cho_solve

    H = np.asarray(H, np.float64)
    A = H.T @ H
    A[np.diag_indices_from(A)] += float(delta)
    return cho_solve(cho_factor(A, lower=True, overwrite_a=True, check_finite=False),
                     H.T @ np.asarray(Y, np.float64).reshape(len(H), -1), check_finite=False)


def exact_weights(Phi: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Eq. 12 of the ntype paper, w = Phi^-1 d (Phi [N, N] over the training inputs, symmetric positive definite
    in exact arithmetic for the kernels here): by Cholesky, by LU where round-off has broken definiteness."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    Y = np.asarray(Y, np.float64).reshape(len(Phi), -1)
    try:
        return cho_solve(cho_factor(np.asarray(Phi, np.float64), lower=True, check_finite=False), Y, check_finite=False)
    except LinAlgError:
        return np.linalg.solve(Phi, Y)


def sweep_predict(d2_train: np.ndarray, Y: np.ndarray, d2_test: np.ndarray, kernel: str, spreads, *,
                  solvers: tuple[str, ...] = ("rls",), bias: bool = True, delta: float = 1e-3
                  ) -> dict[str, dict[float, np.ndarray]]:
    """One RBF network per spread and solver on fixed centres, from the squared distances of the training inputs
    (d2_train [N, K]) and of the test inputs (d2_test [M, K]) to the centres, computed once for the whole sweep
    (and the hidden outputs once per spread for all solvers): {solver: {spread: predictions [M, O]}}.
    "rls": RLS in closed form (ridge_weights) on the hidden outputs plus a constant unit when ``bias``, i.e.
    RBFNetwork(K, spread, kernel, bias, delta).fit(X, Y, centres).predict(X_test) within round-off; "exact":
    eq. 12 (exact_weights, no bias), which needs the centres to be the training inputs (d2_train [N, N])."""
    bad = [s for s in solvers if s not in SOLVERS]
    if bad:
        raise ValueError(f"solver must be one of {SOLVERS}, got {bad}")
    if "exact" in solvers and d2_train.shape[0] != d2_train.shape[1]:
        raise ValueError("solver 'exact' (eq. 12) needs one centre per training sample")
    d_tr = np.sqrt(d2_train) if kernel == "eq9" else None
    d_te = np.sqrt(d2_test) if kernel == "eq9" else None
    out: dict[str, dict[float, np.ndarray]] = {k: {} for k in solvers}
    nb = int(bias and "rls" in solvers)  # the constant unit is the buffers' last column, written once
    Hb = np.empty((d2_train.shape[0], d2_train.shape[1] + nb))
    Htb = np.empty((d2_test.shape[0], d2_test.shape[1] + nb))
    if nb:
        Hb[:, -1] = 1.0
        Htb[:, -1] = 1.0
    K = d2_train.shape[1]
    for s in spreads:
        H, Ht = kernel_phi(kernel, s, d2_train, d_tr, Hb[:, :K]), kernel_phi(kernel, s, d2_test, d_te, Htb[:, :K])
        if "exact" in solvers:
            out["exact"][s] = Ht @ exact_weights(H, Y)
        if "rls" in solvers:
            out["rls"][s] = Htb @ ridge_weights(Hb, Y, delta) if nb else Ht @ ridge_weights(H, Y, delta)
    return out


def half_distance(kernel: str, spread: float) -> float:
    """Distance (input units) at which a unit's output is 0.5."""
    g = kernel_gamma(kernel, spread)
    return math.log(2.0) / g if kernel == "eq9" else math.sqrt(math.log(2.0) / g)


class KMeans:
    """fit(X) -> self; cluster_centers_ [K, F], labels_ [N], inertia_, n_iter_; predict(X) -> labels."""

    def __init__(self, n_clusters: int = 8, max_iter: int = 100, tol: float = 1e-6, seed: int = 0,
                 max_points: int | None = None):
        if n_clusters < 1:
            raise ValueError("n_clusters must be >= 1")
        self.n_clusters = int(n_clusters)
        self.max_iter = int(max_iter)
        self.tol = float(tol)
        self.seed = int(seed)
        self.max_points = max_points  # cluster a random subset of at most this many points (speed)
        self.cluster_centers_: np.ndarray | None = None

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {"n_clusters": self.n_clusters, "max_iter": self.max_iter, "tol": self.tol, "seed": self.seed,
                "max_points": self.max_points}

    def _plusplus(self, X: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        n, k = len(X), self.n_clusters
        C = np.empty((k, X.shape[1]))
        xx = (X * X).sum(1)
        C[0] = X[rng.integers(n)]
        d = sq_dist(X, C[:1], xx)[:, 0]
        for i in range(1, k):
            tot = d.sum()
            j = rng.choice(n, p=d / tot) if tot > 0 else rng.integers(n)
            C[i] = X[j]
            d = np.minimum(d, sq_dist(X, C[i : i + 1], xx)[:, 0])
        return C

    def fit(self, X: np.ndarray) -> KMeans:
        X = np.asarray(X, np.float64).reshape(len(X), -1)
        rng = np.random.default_rng(self.seed)
        if self.max_points is not None and len(X) > self.max_points:
            X = X[rng.choice(len(X), self.max_points, replace=False)]
        k = min(self.n_clusters, len(X))
        self.n_clusters = k
        C = self._plusplus(X, rng)
        scale = max(float(np.var(X, axis=0).sum()), 1e-300)
        xx = (X * X).sum(1)
        for it in range(self.max_iter):
            d = sq_dist(X, C, xx)
            lab = d.argmin(1)
            counts = np.bincount(lab, minlength=k)
            new = np.zeros_like(C)
            np.add.at(new, lab, X)
            empty = counts == 0
            new[~empty] /= counts[~empty, None]
            if empty.any():  # re-seed empty clusters at the points farthest from their centre
                far = np.argsort(-d[np.arange(len(X)), lab])[: int(empty.sum())]
                new[empty] = X[far]
            shift = float(((new - C) ** 2).sum())
            C = new
            if shift <= self.tol * scale:
                break
        self.n_iter_ = it + 1
        d = sq_dist(X, C, xx)
        self.labels_ = d.argmin(1)
        self.inertia_ = float(d[np.arange(len(X)), self.labels_].sum())
        self.cluster_centers_ = C
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        if self.cluster_centers_ is None:
            raise RuntimeError("KMeans: not fitted")
        return sq_dist(np.asarray(X, np.float64).reshape(len(X), -1), self.cluster_centers_).argmin(1)


class RecursiveLeastSquares:
    """Multi-output linear least squares y ~ W^T h, updated one block of rows at a time.

    State: P = (lam-weighted H^T H + delta I)^-1 [K, K] and W [K, O]. A block (H_b [b, K], Y_b [b, O]):
        S = lam I_b + H_b P H_b^T,  G = P H_b^T S^-1,  W += G (Y_b - H_b W),  P = (P - G H_b P) / lam
    (the matrix-inversion lemma; b = 1 is textbook RLS, Haykin, Adaptive Filter Theory, ch. 10). A call with
    more than ``block`` rows (and lam = 1) makes the same update in information form, P' = (P^-1 + H^T H)^-1,
    which costs K^2 b + K^3 instead of b^3 per block. With lam = 1 the result after any split of the data into
    calls is the ridge solution (H^T H + delta I)^-1 H^T Y.
    """

    def __init__(self, delta: float = 1e-3, lam: float = 1.0, block: int = 256):
        if delta <= 0 or not (0 < lam <= 1):
            raise ValueError("need delta > 0 and 0 < lam <= 1")
        self.delta, self.lam, self.block = float(delta), float(lam), int(block)
        self.P: np.ndarray | None = None
        self.W: np.ndarray | None = None
        self.n_samples_seen_ = 0

    def reset(self, n_features: int, n_outputs: int) -> None:
        self.P = np.eye(n_features) / self.delta
        self.W = np.zeros((n_features, n_outputs))
        self.n_samples_seen_ = 0

    def partial_fit(self, H: np.ndarray, Y: np.ndarray) -> RecursiveLeastSquares:
        H = np.asarray(H, np.float64).reshape(len(H), -1)
        Y = np.asarray(Y, np.float64).reshape(len(H), -1)
        if self.P is None:
            self.reset(H.shape[1], Y.shape[1])
        P, W, lam = self.P, self.W, self.lam
        if lam == 1.0 and len(H) > self.block and len(H) >= H.shape[1]:
            # one block of many rows, information form (same update, cheaper when b > K):
            # P' = (P^-1 + H^T H)^-1 = (I + P H^T H)^-1 P,  W' = W + P' H^T (Y - H W)
            A = H.T @ H
            P = np.linalg.solve(np.eye(len(P)) + P @ A, P)
            P = 0.5 * (P + P.T)
            W = W + P @ (H.T @ (Y - H @ W))
        else:
            for i in range(0, len(H), self.block):
                h, y = H[i : i + self.block], Y[i : i + self.block]
                PhT = P @ h.T  # [K, b]
                S = lam * np.eye(len(h)) + h @ PhT
                G = np.linalg.solve(S, PhT.T).T  # [K, b] = P h^T S^-1 (S symmetric)
                W = W + G @ (y - h @ W)
                P = P - G @ PhT.T
                if lam != 1.0:
                    P = P / lam
                P = 0.5 * (P + P.T)  # keep it symmetric against round-off
        self.P, self.W = P, W
        self.n_samples_seen_ += len(H)
        return self

    def fit(self, H: np.ndarray, Y: np.ndarray) -> RecursiveLeastSquares:
        self.P = self.W = None
        return self.partial_fit(H, Y)

    def predict(self, H: np.ndarray) -> np.ndarray:
        if self.W is None:
            raise RuntimeError("RecursiveLeastSquares: not fitted")
        return np.asarray(H, np.float64) @ self.W


class RBFNetwork:
    """Gaussian RBF network: X [N, F] -> Y [N, O].

    fit(X, Y): k-means centres (``n_centres``, at most one per distinct sample), then RLS on the hidden
    outputs (plus a constant unit when ``bias``). partial_fit(X, Y): RLS updates with more data (the first
    call on an unfitted network also places the centres, on that batch). ``centres`` may be given instead of
    k-means (e.g. shared between networks that differ only in spread).
    """

    def __init__(self, n_centres: int = 100, spread: float = 7.0, kernel: str = "matlab", bias: bool = True,
                 delta: float = 1e-3, lam: float = 1.0, block: int = 256, kmeans_iter: int = 100,
                 kmeans_max_points: int | None = 20000, seed: int = 0, solver: str = "rls"):
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}")
        if kernel not in KERNELS:
            raise ValueError("kernel must be 'eq9' (exp(-d / 2 spread^2), the paper's eq. 9 as printed), 'matlab' "
                             "(exp(-ln2 (d / spread)^2)) or 'sigma' (exp(-d^2 / 2 spread^2))")
        if spread <= 0:
            raise ValueError("spread must be > 0")
        self.n_centres, self.spread, self.kernel, self.bias = int(n_centres), float(spread), kernel, bool(bias)
        self.delta, self.lam, self.block = float(delta), float(lam), int(block)
        self.kmeans_iter, self.kmeans_max_points, self.seed = int(kmeans_iter), kmeans_max_points, int(seed)
        self.solver = solver
        self.centres_: np.ndarray | None = None
        self.rls_: RecursiveLeastSquares | None = None

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {k: getattr(self, k) for k in ("n_centres", "spread", "kernel", "bias", "delta", "lam", "block",
                                              "kmeans_iter", "kmeans_max_points", "seed", "solver")}

    @property
    def gamma(self) -> float:
        """phi(d) = exp(-gamma d^2) ("matlab", "sigma") or exp(-gamma d) ("eq9")."""
        return kernel_gamma(self.kernel, self.spread)

    def hidden(self, X: np.ndarray) -> np.ndarray:
        """[N, F] -> [N, K (+1)] hidden-layer outputs."""
        X = np.asarray(X, np.float64).reshape(len(X), -1)
        H = kernel_phi(self.kernel, self.spread, sq_dist(X, self.centres_))
        return np.concatenate([H, np.ones((len(X), 1))], 1) if self.bias and self.solver == "rls" else H

    def place_centres(self, X: np.ndarray) -> np.ndarray:
        km = KMeans(self.n_centres, self.kmeans_iter, seed=self.seed, max_points=self.kmeans_max_points)
        return km.fit(X).cluster_centers_

    def fit(self, X: np.ndarray, Y: np.ndarray, centres: np.ndarray | None = None) -> RBFNetwork:
        X = np.asarray(X, np.float64).reshape(len(X), -1)
        self.centres_ = np.asarray(centres, np.float64) if centres is not None else self.place_centres(X)
        self.rls_ = None
        if self.solver == "exact":  # eq. 12: w = Phi^-1 d, Phi [N, N] over the training inputs, no bias unit
            if len(self.centres_) != len(X):
                raise ValueError("solver 'exact' (eq. 12) needs one centre per training sample")
            Phi = kernel_phi(self.kernel, self.spread, sq_dist(X, self.centres_))
            self.rls_ = RecursiveLeastSquares(self.delta, self.lam, self.block)
            self.rls_.W = exact_weights(Phi, Y)
            self.rls_.n_samples_seen_ = len(X)
            return self
        return self.partial_fit(X, Y)

    def partial_fit(self, X: np.ndarray, Y: np.ndarray) -> RBFNetwork:
        if self.solver == "exact":
            raise ValueError("solver 'exact' (eq. 12) is a batch solve: use fit")
        X = np.asarray(X, np.float64).reshape(len(X), -1)
        if self.centres_ is None:
            self.centres_ = self.place_centres(X)
        if self.rls_ is None:
            self.rls_ = RecursiveLeastSquares(self.delta, self.lam, self.block)
        self.rls_.partial_fit(self.hidden(X), np.asarray(Y, np.float64).reshape(len(X), -1))
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        if self.rls_ is None:
            raise RuntimeError("RBFNetwork: not fitted")
        return self.rls_.predict(self.hidden(X))

    @property
    def coef_(self) -> np.ndarray:
        return self.rls_.W


@register("rbf")
class RBFCompensator(Compensator):
    """ntype paper's RBFNN as a static compensator over whatever input channels it is given: each input
    feature min-max mapped onto [0, input_span] (training set; the paper's eq. 13 with a 9 kOhm span for
    R_z), then RBFNetwork on the current sample. Targets are z-scored (undone at the output).
    ``partial_fit`` continues the RLS with more (physical-unit) data."""

    DEFAULTS = {"n_centres": 100, "spread": 7.0, "kernel": "matlab", "delta": 1e-3, "input_span": 9.0, "block": 256}

    def _scale(self, z: np.ndarray) -> np.ndarray:
        return (np.asarray(z, np.float64) - self._lo) * self._k

    def _fit(self, zx, zy, zv, *, seed, progress):
        Z = np.concatenate(zx)
        self._lo = Z.min(0)
        span = np.maximum(Z.max(0) - self._lo, 1e-12)
        self._k = float(self.hparams["input_span"]) / span
        h = self.hparams
        self.net = RBFNetwork(h["n_centres"], h["spread"], h["kernel"], delta=h["delta"], block=h["block"], seed=seed)
        self.net.fit(self._scale(Z), np.concatenate(zy))
        return {"n_samples": len(Z), "n_centres": len(self.net.centres_)}

    def partial_fit(self, x: np.ndarray, y: np.ndarray) -> RBFCompensator:
        self._check_fitted()
        self.net.partial_fit(self._scale(self.x_norm.apply(np.asarray(x).reshape(len(x), -1))),
                             self.y_norm.apply(np.asarray(y).reshape(len(y), -1)))
        return self

    def _predict_z(self, z):
        return self.net.predict(self._scale(z))

    def _streamer(self) -> Streamer:
        return FnStreamer(self, lambda z: self.net.predict(self._scale(z)[None])[0])

    def state_tensors(self):
        r = self.net.rls_
        return {"centres": self.net.centres_, "W": r.W, "P": r.P, "lo": self._lo, "k": self._k,
                "n_samples_seen": np.asarray([r.n_samples_seen_], np.int64)}

    def load_state_tensors(self, t):
        h = self.hparams
        self.net = RBFNetwork(h["n_centres"], h["spread"], h["kernel"], delta=h["delta"], block=h["block"], seed=self.seed)
        self.net.centres_ = np.asarray(t["centres"], np.float64)
        self.net.rls_ = RecursiveLeastSquares(h["delta"], 1.0, h["block"])
        self.net.rls_.W = np.asarray(t["W"], np.float64)
        self.net.rls_.P = np.asarray(t["P"], np.float64)
        self.net.rls_.n_samples_seen_ = int(t["n_samples_seen"][0])
        self._lo, self._k = np.asarray(t["lo"], np.float64), np.asarray(t["k"], np.float64)

"""The velostat paper's compensators (paper key `velostat`, sects. 3.2 and 4.2), as estimators.

  KMeans            K-means with the absolute-distance criterion (eqs. 4-5) and the paper's stopping
                    criterion G_J (eq. 6); fit / predict / partial_fit (online MacQueen update)
  gj_criterion      G_J = sum_k p_k s*_k, s*_k the mean absolute distance between members of cluster k
  silhouette_samples, silhouette_score   eq. 7 (with the usual sign: s = (b - a) / max(a, b)); an exact
                    O(N log N) path for 1-D data, so the whole delta data space is scored
  semi_trapezoid    eqs. 8-9: T1 (loading) and T2 (creep) memberships on the relative variation delta
  CreepTracker      creep tracking compensation: delta (eq. 3) -> fuzzy stage recognition (maximum
                    membership) -> eq. 2 subtraction of the creep of the current and all previous creep
                    stages; fit (K-means on delta of unlabelled recordings), partial_fit, predict, stream()
  BPCompensator     registry "bp": the paper's BP network (sect. 4.2): inputs (unit or cluster, R), one
                    sigmoid hidden layer, purelin output, min-max inputs (eq. 24), Adam + mini-batches
  search_hidden     the hidden-node search over 3..12 (eq. 16), best by validation RMSE
"""

from __future__ import annotations

from collections.abc import Sequence as Seq
from typing import Any

import numpy as np
import torch
from torch import nn

from learn.models.base import FnStreamer, Streamer, register
from learn.models.neural import TRAIN_DEFAULTS, TorchCompensator, _f32

__all__ = [
    "PAPER_BOUNDS",
    "BPCompensator",
    "CreepTracker",
    "KMeans",
    "gj_criterion",
    "search_hidden",
    "semi_trapezoid",
    "silhouette_samples",
    "silhouette_score",
]

PAPER_BOUNDS = (0.00612, 0.02374)  # eqs. 8-9: the paper's transitional band of delta


# ---------------------------------------------------------------------------------------------- K-means


def _as2d(X) -> np.ndarray:
    X = np.asarray(X, np.float64)
    return X.reshape(-1, 1) if X.ndim == 1 else X


def _mean_pairwise_1d(v: np.ndarray) -> float:
    """Mean |v_i - v_j| over unordered pairs i < j (sorted prefix form, O(N log N))."""
    n = len(v)
    if n < 2:
        return 0.0
    s = np.sort(v)
    tot = float(np.sum(s * (2 * np.arange(n) - n + 1)))
    return 2.0 * tot / (n * (n - 1))


def _mean_pairwise(X: np.ndarray) -> float:
    if X.shape[1] == 1:
        return _mean_pairwise_1d(X[:, 0])
    n = len(X)
    if n < 2:
        return 0.0
    d = np.linalg.norm(X[:, None, :] - X[None, :, :], axis=-1)
    return float(d.sum() / (n * (n - 1)))


def gj_criterion(X, labels, n_clusters: int | None = None) -> float:
    """Eq. 6: G_J = sum_k p_k s*_k with p_k = N_k / N and s*_k the mean distance between the members of
    cluster k (the paper writes 2 / (N_k (N_k - 1)) times the double sum; we read the double sum over
    pairs i < j, so that s*_k is the average distance the text describes)."""
    X, labels = _as2d(X), np.asarray(labels)
    K = int(n_clusters if n_clusters is not None else labels.max() + 1)
    n = len(X)
    return float(sum((np.sum(labels == k) / n) * _mean_pairwise(X[labels == k]) for k in range(K)))


class KMeans:
    """K-means (eqs. 4-5), stopping when the centres no longer change or G_J (eq. 6) stops decreasing.

    init "quantile": the samples at the quantiles (k + 1/2) / K of the first feature (deterministic; the
    paper picks "3 sets of sample data" as initial centres); "k-means++": seeded D^2 sampling, n_init runs,
    the lowest G_J kept. For 1-D data the centres are sorted ascending, so label 0 is the smallest."""

    def __init__(self, n_clusters: int = 3, init: str = "quantile", n_init: int = 1, max_iter: int = 300,
                 tol: float = 0.0, seed: int = 0):
        if init not in ("quantile", "k-means++"):
            raise ValueError(f"init must be 'quantile' or 'k-means++', got {init!r}")
        self.n_clusters, self.init, self.n_init = int(n_clusters), init, int(n_init)
        self.max_iter, self.tol, self.seed = int(max_iter), float(tol), int(seed)
        self.cluster_centers_: np.ndarray | None = None
        self.counts_: np.ndarray | None = None

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {"n_clusters": self.n_clusters, "init": self.init, "n_init": self.n_init, "max_iter": self.max_iter,
                "tol": self.tol, "seed": self.seed}

    def _init(self, X: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        K = self.n_clusters
        if self.init == "quantile":
            order = np.argsort(X[:, 0], kind="stable")
            return X[order[((np.arange(K) + 0.5) / K * len(X)).astype(int)]].copy()
        c = [X[rng.integers(len(X))]]
        for _ in range(1, K):
            d2 = np.min(((X[:, None, :] - np.asarray(c)[None]) ** 2).sum(-1), axis=1)
            c.append(X[rng.choice(len(X), p=d2 / d2.sum())] if d2.sum() > 0 else X[rng.integers(len(X))])
        return np.asarray(c)

    @staticmethod
    def _assign(X: np.ndarray, c: np.ndarray) -> np.ndarray:
        if X.shape[1] == 1:
            return np.argmin(np.abs(X[:, :1] - c[None, :, 0]), axis=1)  # eq. 4: absolute distance
        return np.argmin(((X[:, None, :] - c[None]) ** 2).sum(-1), axis=1)

    def _run(self, X: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[float], int]:
        K = self.n_clusters
        hist: list[float] = []
        best = (np.inf, c, None)
        it = 0
        for it in range(1, self.max_iter + 1):
            lab = self._assign(X, c)
            new = np.array([X[lab == k].mean(0) if np.any(lab == k) else c[k] for k in range(K)])  # eq. 5
            lab = self._assign(X, new)
            gj = gj_criterion(X, lab, K)
            hist.append(gj)
            if gj < best[0]:
                best = (gj, new, lab)
            moved = not np.allclose(new, c, rtol=0, atol=0)
            c = new
            if not moved or (len(hist) > 1 and gj >= hist[-2] - self.tol * abs(hist[-2])):
                break
        return best[1], best[2], hist, it

    def fit(self, X) -> KMeans:
        X = _as2d(X)
        if len(X) < self.n_clusters:
            raise ValueError(f"KMeans: {len(X)} samples for {self.n_clusters} clusters")
        rng = np.random.default_rng(self.seed)
        best = None
        for _ in range(self.n_init if self.init == "k-means++" else 1):
            c, lab, hist, it = self._run(X, self._init(X, rng))
            if best is None or hist and min(hist) < best[2]:
                best = (c, lab, min(hist), hist, it)
        c, lab, gj, hist, it = best
        if X.shape[1] == 1:
            order = np.argsort(c[:, 0])
            c = c[order]
            lab = np.argsort(order)[lab]
        self.cluster_centers_, self.labels_ = c, lab
        self.counts_ = np.bincount(lab, minlength=self.n_clusters).astype(np.float64)
        self.gj_, self.gj_history_, self.n_iter_ = float(gj_criterion(X, lab, self.n_clusters)), hist, it
        self.inertia_ = float(((X - c[lab]) ** 2).sum())
        return self

    def predict(self, X) -> np.ndarray:
        if self.cluster_centers_ is None:
            raise RuntimeError("KMeans: not fitted")
        return self._assign(_as2d(X), self.cluster_centers_)

    def partial_fit(self, X) -> KMeans:
        """Online update (MacQueen): each sample moves its nearest centre by 1/n_k of the gap; the first
        call on an unfitted estimator is a full fit."""
        X = _as2d(X)
        if self.cluster_centers_ is None:
            return self.fit(X)
        c, n = self.cluster_centers_.copy(), self.counts_.copy()
        for x in X:
            k = int(self._assign(x[None], c)[0])
            n[k] += 1
            c[k] += (x - c[k]) / n[k]
        if c.shape[1] == 1:
            order = np.argsort(c[:, 0])
            c, n = c[order], n[order]
        self.cluster_centers_, self.counts_ = c, n
        return self


# ---------------------------------------------------------------------------------------------- silhouette


def _silhouette_1d(x: np.ndarray, labels: np.ndarray) -> np.ndarray:
    ks = np.unique(labels)
    n = len(x)
    # mean distance from every sample to every cluster, via sorted values and prefix sums
    D = np.empty((n, len(ks)))
    for j, k in enumerate(ks):
        v = np.sort(x[labels == k])
        cs = np.concatenate([[0.0], np.cumsum(v)])
        m = np.searchsorted(v, x, side="right")
        below = x * m - cs[m]
        above = (cs[-1] - cs[m]) - x * (len(v) - m)
        D[:, j] = below + above
    return _silhouette_from_sums(D, labels, ks)


def _silhouette_from_sums(D: np.ndarray, labels: np.ndarray, ks: np.ndarray) -> np.ndarray:
    """s(i) from D[i, j] = sum of distances from sample i to the members of cluster ks[j]."""
    n = len(labels)
    cnt = np.array([np.sum(labels == k) for k in ks], float)
    own = np.searchsorted(ks, labels)
    a_den = cnt[own] - 1
    a = np.where(a_den > 0, D[np.arange(n), own] / np.maximum(a_den, 1), 0.0)
    Dm = D / cnt[None]
    Dm[np.arange(n), own] = np.inf
    b = Dm.min(axis=1)
    s = (b - a) / np.maximum(np.maximum(a, b), 1e-300)
    return np.where(a_den > 0, s, 0.0)


def silhouette_samples(X, labels) -> np.ndarray:
    """Eq. 7 per sample: s(i) = (b(i) - a(i)) / max(a(i), b(i)); a(i) the mean distance to the other members
    of its cluster, b(i) the smallest mean distance to another cluster; 0 for a singleton cluster. (The paper
    prints a(i) - b(i), a sign slip: its 0.931 and 'closer to 1 is better' need b - a.)"""
    X, labels = _as2d(X), np.asarray(labels)
    if len(np.unique(labels)) < 2:
        raise ValueError("silhouette needs at least 2 clusters")
    if X.shape[1] == 1:
        return _silhouette_1d(X[:, 0], labels)
    ks = np.unique(labels)
    n = len(X)
    D = np.zeros((n, len(ks)))
    for i0 in range(0, n, 512):
        d = np.linalg.norm(X[i0:i0 + 512, None, :] - X[None], axis=-1)
        for j, k in enumerate(ks):
            D[i0:i0 + 512, j] = d[:, labels == k].sum(1)
    return _silhouette_from_sums(D, labels, ks)


def silhouette_score(X, labels) -> float:
    """Eq. 7: the mean of silhouette_samples."""
    return float(np.mean(silhouette_samples(X, labels)))


# ---------------------------------------------------------------------------------------------- fuzzy stages


def semi_trapezoid(delta, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. 8-9: T1 (loading/unloading) = 0 below lo, rising linearly to 1 at hi; T2 (creep) = 1 - T1."""
    if not hi > lo:
        raise ValueError(f"semi_trapezoid needs hi > lo (got {lo}, {hi})")
    t1 = np.clip((np.asarray(delta, np.float64) - lo) / (hi - lo), 0.0, 1.0)
    return t1, 1.0 - t1


LOADING, CREEP, OPEN = 1, 0, -1


class CreepTracker:
    """Creep tracking compensation (sect. 3.2) of a resistance signal, sample by sample.

    delta_t = |r_t - r_{t-lag}| / r_t (eq. 3) on r = the causal moving average of R over `smooth` samples
    (the paper's "period" is not given; at our 10 Hz and 20 ohm readout noise a raw sample-to-sample delta is
    noise, see the report). Stage: loading/unloading if T1(delta) > T2(delta), else creep (maximum
    membership). Eq. 2, in `domain` "resistance" (the paper's R) or "conductance" (1/R, ours: the film's
    creep adds conductance, so the offsets carry across force levels):
        loading/unloading:  v_f = v_t - A            (A = creep accumulated over the previous creep stages)
        creep:              v_f = v_t - A - (v_t - v_c) = v_c - A   (v_c: value where the creep stage began)
    and A += v_end - v_c when a creep stage ends. R >= r_open (no contact, the source at compliance) resets A.

    fit(R sequences): K-means (3 clusters, G_J) on delta of the in-contact samples; the memberships' lo/hi are
    the decision boundaries between the creep/transitional and transitional/loading clusters (kmeans_bounds_),
    unless `bounds` were given (e.g. the paper's PAPER_BOUNDS): then those stay in use.
    """

    def __init__(self, n_clusters: int = 3, smooth: int = 5, lag: int = 1, domain: str = "conductance",
                 r_open: float | None = None, open_frac: float = 0.5, init: str = "quantile", seed: int = 0,
                 bounds: tuple[float, float] | None = None):
        if domain not in ("resistance", "conductance"):
            raise ValueError(f"domain must be 'resistance' or 'conductance', got {domain!r}")
        self.n_clusters, self.smooth, self.lag, self.domain = int(n_clusters), int(smooth), int(lag), domain
        self.r_open, self.open_frac, self.init, self.seed = r_open, float(open_frac), init, int(seed)
        self.bounds = None if bounds is None else (float(bounds[0]), float(bounds[1]))
        self.fixed_bounds = bounds is not None  # given: fit() still clusters (kmeans_bounds_) but keeps these
        self.kmeans_bounds_: tuple[float, float] | None = None
        self.kmeans: KMeans | None = None
        self.silhouette_: float | None = None

    # -- features
    def smoothed(self, r) -> np.ndarray:
        r = np.asarray(r, np.float64).ravel()
        w = self.smooth
        pad = np.concatenate([np.repeat(r[:1], w - 1), r])
        return np.convolve(pad, np.ones(w) / w, mode="valid")

    def delta(self, r) -> tuple[np.ndarray, np.ndarray]:
        """(delta [T], valid [T]): eq. 3 on the smoothed signal; valid where r_t and r_{t-lag} are in contact."""
        r = np.asarray(r, np.float64).ravel()
        s = self.smoothed(r)
        prev = np.concatenate([np.repeat(s[:1], self.lag), s[:-self.lag]])
        rprev = np.concatenate([np.repeat(r[:1], self.lag + self.smooth - 1), r])[: len(r)]
        d = np.abs(s - prev) / s
        ro = self.r_open if self.r_open is not None else np.inf
        valid = (r < ro) & (rprev < ro)
        return d, valid

    def _data(self, rs) -> np.ndarray:
        if isinstance(rs, np.ndarray) and rs.ndim == 1:
            rs = [rs]
        return np.concatenate([d[v] for d, v in (self.delta(r) for r in rs)])

    # -- estimator API
    def fit(self, rs: Seq[np.ndarray], score: bool = True) -> CreepTracker:
        rs = [np.asarray(r, np.float64).ravel() for r in ([rs] if isinstance(rs, np.ndarray) and rs.ndim == 1 else rs)]
        if self.r_open is None:
            self.r_open = self.open_frac * max(float(r.max()) for r in rs)
        d = self._data(rs)
        self.kmeans = KMeans(self.n_clusters, init=self.init, seed=self.seed).fit(d)
        self.n_samples_seen_ = len(d)
        self._set_bounds()
        self.silhouette_ = silhouette_score(d, self.kmeans.labels_) if score else None
        return self

    def partial_fit(self, rs) -> CreepTracker:
        """Online update of the stage clusters (and so of the memberships) with more recordings."""
        if self.kmeans is None:
            return self.fit(rs)
        d = self._data(rs)
        self.kmeans.partial_fit(d)
        self.n_samples_seen_ += len(d)
        self._set_bounds()
        return self

    def _set_bounds(self) -> None:
        c = np.sort(self.kmeans.cluster_centers_[:, 0])
        mids = 0.5 * (c[1:] + c[:-1])
        self.kmeans_bounds_ = (float(mids[0]), float(mids[-1]))
        if not self.fixed_bounds:
            self.bounds = self.kmeans_bounds_

    def memberships(self, delta) -> tuple[np.ndarray, np.ndarray]:
        return semi_trapezoid(delta, *self._b())

    def _b(self) -> tuple[float, float]:
        if self.bounds is None:
            raise RuntimeError("CreepTracker: not fitted (and no bounds given)")
        return self.bounds

    def predict(self, r) -> np.ndarray:
        """Compensated resistance [T] (ohm) of one recording."""
        return self.transform(r)[0]

    def transform(self, r) -> tuple[np.ndarray, np.ndarray]:
        """(compensated R [T], stage [T]: 1 loading/unloading, 0 creep, -1 no contact)."""
        st = self.stream()
        out = np.array([st.step(v) for v in np.asarray(r, np.float64).ravel()])
        return out[:, 0], out[:, 1].astype(int)

    def stream(self) -> CreepStreamer:
        self._b()
        return CreepStreamer(self)

    def state(self) -> dict[str, Any]:
        km = self.kmeans
        return {"n_clusters": self.n_clusters, "smooth": self.smooth, "lag": self.lag, "domain": self.domain,
                "r_open": self.r_open, "bounds": list(self._b()),
                "centres": None if km is None else km.cluster_centers_[:, 0].tolist(),
                "counts": None if km is None else km.counts_.tolist(), "gj": None if km is None else km.gj_,
                "silhouette": self.silhouette_}

    @classmethod
    def from_state(cls, s: dict[str, Any]) -> CreepTracker:
        t = cls(s["n_clusters"], s["smooth"], s["lag"], s["domain"], s["r_open"], bounds=tuple(s["bounds"]))
        t.silhouette_ = s.get("silhouette")
        return t


class CreepStreamer(Streamer):
    """One resistance sample in, (compensated R, stage) out; state: the smoothing window, the lag buffer,
    the current stage, the creep start value v_c and the accumulated creep A."""

    def __init__(self, tr: CreepTracker):
        self.tr = tr
        self.lo, self.hi = tr._b()
        self.ro = tr.r_open if tr.r_open is not None else np.inf
        self.reset()

    def reset(self) -> None:
        self.win: list[float] = []
        self.hist: list[float] = []
        self.raw: list[float] = []
        self.stage = LOADING
        self.acc = 0.0
        self.vc = None
        self.vlast = None

    def _v(self, r: float) -> float:
        return r if self.tr.domain == "resistance" else 1.0 / r

    def _r(self, v: float) -> float:
        if self.tr.domain == "resistance":
            return max(v, 1e-6)
        return 1.0 / max(v, 1e-12)

    def step(self, x) -> np.ndarray:
        r = float(np.asarray(x).ravel()[0])
        tr = self.tr
        if not self.win:
            self.win = [r] * tr.smooth
            self.raw = [r] * (tr.lag + tr.smooth)
        self.win = self.win[1:] + [r]
        self.raw = self.raw[1:] + [r]
        s = sum(self.win) / tr.smooth
        if not self.hist:
            self.hist = [s] * tr.lag
        prev = self.hist[0]
        self.hist = self.hist[1:] + [s]
        if r >= self.ro or self.raw[0] >= self.ro:  # no contact (or just made): nothing to compensate
            if r >= self.ro:
                self.acc, self.vc, self.stage = 0.0, None, OPEN
                return np.array([r, OPEN], float)
        d = abs(s - prev) / s
        t1 = min(max((d - self.lo) / (self.hi - self.lo), 0.0), 1.0)
        v = self._v(s)
        loading = t1 > 1.0 - t1 or self.stage == OPEN
        if loading:
            if self.stage == CREEP and self.vc is not None:
                self.acc += self.vlast - self.vc  # creep of the stage that just ended
            self.stage, self.vc = LOADING, None
            out = v - self.acc
        else:
            if self.stage != CREEP:
                self.vc = v
            self.stage = CREEP
            out = self.vc - self.acc  # = v_t - A - (v_t - v_c)
        self.vlast = v
        return np.array([self._r(out), self.stage], float)


# ---------------------------------------------------------------------------------------------- BP network


class BPNet(nn.Module):
    """Eqs. 19-20: H = sigmoid(W x - theta_h), f = v H - theta (one hidden layer, purelin output)."""

    def __init__(self, n_in: int, hidden: int, n_out: int):
        super().__init__()
        self.hidden = nn.Linear(n_in, hidden)
        self.out = nn.Linear(hidden, n_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(torch.sigmoid(self.hidden(x)))


BP_R_INPUTS = ("ohm", "log", "conductance")
BP_ENCODINGS = ("index", "onehot")


class _EncodedStreamer(Streamer):
    """Streams (id, R) samples through the BP net: the input transform, then the net's own streamer."""

    def __init__(self, comp: BPCompensator, inner: Streamer):
        self.comp, self.inner = comp, inner

    def reset(self) -> None:
        self.inner.reset()

    def step(self, x) -> np.ndarray:
        return self.inner.step(self.comp.encode(np.asarray(x, np.float64).reshape(1, -1))[0])


@register("bp")
class BPCompensator(TorchCompensator):
    """The paper's force model F = f^-1(Unit, R_F) (eq. 15): inputs (unit or cluster id, resistance),
    `hidden` sigmoid nodes (3-12, eq. 16), purelin output; inputs min-max scaled to [0, 1] on the training set
    (eq. 24); Adam, learning rate 0.01, mini-batches (sect. 4.2). Static: the current sample only.

    Input transform (applied to the raw (id, R in ohm) columns before the min-max scaling):
      r_input   "ohm" (the paper's literal R), "log" (ln R) or "conductance" (1/R in mS)
      encoding  "index" (the paper's scalar unit/cluster number) or "onehot" (n_ids columns; ids outside
                [0, n_ids) are clipped; n_ids = 0 takes max id + 1 of the training data)
    The defaults are the paper's literal inputs; `predict`/`stream` always take the raw (id, R) columns."""

    DEFAULTS = {**TRAIN_DEFAULTS, "hidden": 8, "lr": 0.01, "batch_size": 32, "max_epochs": 500, "patience": 60,
                "grad_clip": None, "r_input": "ohm", "encoding": "index", "n_ids": 0}

    def __init__(self, **hparams: Any):
        super().__init__(**hparams)
        if self.hparams["r_input"] not in BP_R_INPUTS:
            raise ValueError(f"bp: r_input must be one of {BP_R_INPUTS}, got {self.hparams['r_input']!r}")
        if self.hparams["encoding"] not in BP_ENCODINGS:
            raise ValueError(f"bp: encoding must be one of {BP_ENCODINGS}, got {self.hparams['encoding']!r}")

    def encode(self, x: np.ndarray) -> np.ndarray:
        """Raw [T, 2] (id, R ohm) -> the net's input columns (before min-max)."""
        x = np.asarray(x, np.float64).reshape(len(x), -1)
        ident, r = x[:, 0], np.maximum(x[:, 1], 1e-9)
        h = self.hparams
        rr = {"ohm": r, "log": np.log(np.maximum(r, 1e-9)), "conductance": 1e3 / r}[h["r_input"]]
        if h["encoding"] == "index":
            return np.column_stack([ident, rr])
        n = int(h["n_ids"])
        oh = np.zeros((len(x), n))
        oh[np.arange(len(x)), np.clip(np.rint(ident).astype(int), 0, n - 1)] = 1.0
        return np.column_stack([oh, rr])

    def fit(self, xs, ys, valid=None, **kw) -> BPCompensator:
        if self.hparams["encoding"] == "onehot" and int(self.hparams["n_ids"]) <= 0:
            self.hparams["n_ids"] = int(max(np.rint(np.asarray(x)[:, 0]).max() for x in xs)) + 1
        xs = [self.encode(x) for x in xs]
        if valid is not None:
            valid = ([self.encode(x) for x in valid[0]], valid[1])
        return super().fit(xs, ys, valid, **kw)

    def predict(self, x):
        if isinstance(x, (list, tuple)):
            return [self.predict(v) for v in x]
        return super().predict(self.encode(x))

    def stream(self) -> Streamer:
        return _EncodedStreamer(self, super().stream())

    def _build(self):
        return BPNet(self.n_in, int(self.hparams["hidden"]), self.n_out)

    def _fit(self, zx, zy, zv, *, seed, progress):
        a = np.concatenate(zx)
        span = a.max(0) - a.min(0)
        # a constant column (e.g. an id absent from the training data) maps to 0 rather than blowing up
        self._lo, self._span = a.min(0), np.where(span > 1e-12, span, 1.0)
        return super()._fit(zx, zy, zv, seed=seed, progress=progress)

    def _mm(self, z: np.ndarray) -> np.ndarray:
        return (np.asarray(z, np.float64) - self._lo) / self._span  # eq. 24

    def _examples(self, zx, zy, train):
        return _f32(self._mm(np.concatenate(zx))), _f32(np.concatenate(zy))

    def _forward_seq(self, z):
        return self.net(_f32(self._mm(z))).double().numpy()

    def _streamer(self) -> Streamer:
        net = self.net

        def f(z: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                return net(_f32(self._mm(z[None])))[0].double().numpy()

        return FnStreamer(self, f)

    def state_tensors(self):
        return {**super().state_tensors(), "minmax.lo": np.asarray(self._lo), "minmax.span": np.asarray(self._span)}

    def load_state_tensors(self, tensors):
        t = dict(tensors)
        self._lo, self._span = np.asarray(t.pop("minmax.lo"), np.float64), np.asarray(t.pop("minmax.span"), np.float64)
        super().load_state_tensors(t)


def _fit_bp(h: int, xs, ys, valid, seed: int, hp: dict[str, Any]) -> BPCompensator:
    """One net of the hidden-node search (a worker process of search_hidden: torch on one thread, CPU)."""
    from learn.train import training_device

    torch.set_num_threads(1)
    with training_device("cpu"):
        return BPCompensator(hidden=int(h), **hp).fit(xs, ys, valid=valid, seed=seed)


def search_hidden(xs, ys, valid, hidden: Seq[int] = range(3, 13), seed: int = 0, workers: int = 1,
                  **hp) -> tuple[BPCompensator, dict[int, float]]:
    """Train one BP net per hidden-node count (eq. 16: 3..12) and keep the lowest validation RMSE (N).

    workers > 1: the nets train side by side in that many spawned processes, each on the CPU with torch on one
    thread (the nets are independent and seeded alike: the same weights as one after another on one thread,
    tested); workers = 1 trains them here, on the current training device."""
    if workers > 1 and len(hidden) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(int(workers), len(hidden)), mp_context=mp.get_context("spawn")) as ex:
            futs = [ex.submit(_fit_bp, int(h), xs, ys, valid, seed, hp) for h in hidden]
            comps = [f.result() for f in futs]
    else:
        comps = (BPCompensator(hidden=int(h), **hp).fit(xs, ys, valid=valid, seed=seed) for h in hidden)
    scores: dict[int, float] = {}
    best: tuple[float, BPCompensator | None] = (np.inf, None)
    for h, comp in zip(hidden, comps):
        e = np.concatenate([comp.predict(x)[:, 0] - np.asarray(y).reshape(len(y), -1)[:, 0] for x, y in zip(*valid)])
        scores[int(h)] = float(np.sqrt(np.mean(e**2)))
        if scores[int(h)] < best[0]:
            best = (scores[int(h)], comp)
    return best[1], scores

"""A seed ensemble of any registered compensator: members of one kind and one set of hyper-parameters,
trained on the same data with training seeds seed, seed+1, ..., seed+n-1; the estimate is their mean.

Why: a small net's error at a rarely-seen operating point (an extrapolation) moves with the training seed
much more than its average error does; averaging a few seeds cancels much of that spread at n times the
training and inference cost.

    predict(x) = mean_k member_k.predict(x)          (physical units)
    stream()   steps every member's streamer and averages (equal to predict on the same sequence)
    context    = the largest member context

Checkpoint (learn.checkpoint, no pickle): config.json holds the ensemble's kind ("ensemble") and its
hyper-parameters {member, n_members, member_hparams}; model.safetensors holds every member's tensors under
``member{k}.`` and each member's z-score statistics as ``member{k}.norm.{x,y}_{mean,std}``, so a member is
rebuilt exactly as it was fitted (the ensemble's own norms in config.json are member 0's).
"""

from __future__ import annotations

from collections.abc import Sequence as Seq
from typing import Any

import numpy as np

from learn.models.base import (
    MODELS,
    Compensator,
    Streamer,
    load_builtin_models,
    make_model,
    register,
)
from learn.normalize import ZScore

__all__ = ["Ensemble", "EnsembleStreamer", "fit_ensembles"]

_NORM = ("x_mean", "x_std", "y_mean", "y_std")
HISTORY_CURVES = ("train_loss", "valid_loss")


@register("ensemble")
class Ensemble(Compensator):
    """``make_model("ensemble", member="tcn", n_members=3, member_hparams={...})``."""

    # batched: the members trained as one batched network (`fit_ensembles`; members of kind tcn only): the
    # same training as one member after another up to float summation order, a fraction of the time on a GPU
    DEFAULTS = {"member": "tcn", "n_members": 3, "member_hparams": {}, "batched": False}

    def __init__(self, **hparams: Any):
        super().__init__(**hparams)
        load_builtin_models()  # the member kinds register themselves

        h = self.hparams
        if h["member"] not in MODELS or h["member"] == "ensemble":
            raise ValueError(f"ensemble: member must be a registered model other than 'ensemble', got {h['member']!r}")
        if int(h["n_members"]) < 1:
            raise ValueError(f"ensemble: n_members must be >= 1, got {h['n_members']}")
        self.hparams["n_members"] = int(h["n_members"])
        self.hparams["member_hparams"] = dict(h["member_hparams"] or {})
        make_model(h["member"], **self.hparams["member_hparams"])  # unknown member hyper-parameters fail now
        self.members: list[Compensator] = []

    @property
    def temporal(self) -> bool:  # type: ignore[override]
        return bool(MODELS[self.hparams["member"]].temporal)

    @property
    def context(self) -> int:
        if self.members:
            return max(m.context for m in self.members)
        return make_model(self.hparams["member"], **self.hparams["member_hparams"]).context

    def _new_member(self) -> Compensator:
        return make_model(self.hparams["member"], **self.hparams["member_hparams"])

    # ------------------------------------------------------------------ fit / predict

    def fit(self, xs, ys, valid=None, *, seed: int = 0, progress: bool = False, inputs: Seq[str] = (),
            targets: Seq[str] = (), units: dict[str, str] | None = None) -> Ensemble:
        if self.hparams["batched"]:
            fit_ensembles([(self, {"xs": xs, "ys": ys, "valid": valid, "seed": seed, "inputs": inputs,
                                   "targets": targets, "units": units})])
            return self
        self.members = []
        for k in range(self.hparams["n_members"]):
            m = self._new_member()
            m.fit(xs, ys, valid, seed=int(seed) + k, progress=progress, inputs=inputs, targets=targets, units=units)
            self.members.append(m)
        self._finish(seed)
        return self

    def _finish(self, seed: int) -> None:
        m0 = self.members[0]
        self.n_in, self.n_out = m0.n_in, m0.n_out
        self.inputs, self.targets, self.units = list(m0.inputs), list(m0.targets), dict(m0.units)
        self.x_norm, self.y_norm = m0.x_norm, m0.y_norm
        self.seed = int(seed)
        summ = [{k: v for k, v in m.history.items() if k not in HISTORY_CURVES} for m in self.members]
        self.history = {"member_seeds": [int(seed) + k for k in range(len(self.members))], "members": summ}
        secs = [s.get("seconds") for s in summ]
        if all(isinstance(s, (int, float)) for s in secs):
            # batched members each report the group's wall time: count it once
            self.history["seconds"] = float(secs[0] if self.hparams["batched"] else sum(secs))

    def _fit(self, zx, zy, zv, *, seed, progress):  # fit() is overridden: members normalise their own data
        raise NotImplementedError

    def predict(self, x):
        if isinstance(x, (list, tuple)):
            return [self.predict(v) for v in x]
        self._check_fitted()
        return np.mean([m.predict(x) for m in self.members], axis=0)

    def predict_members(self, x) -> list[np.ndarray]:
        """Each member's estimate of one episode (physical units), in member order."""
        self._check_fitted()
        return [m.predict(x) for m in self.members]

    def _predict_z(self, z):
        return self.y_norm.apply(self.predict(self.x_norm.invert(z)))

    def _check_fitted(self) -> None:
        super()._check_fitted()
        if not self.members:
            raise RuntimeError("ensemble: not fitted")

    def _streamer(self) -> Streamer:
        return EnsembleStreamer([m.stream() for m in self.members])

    # ------------------------------------------------------------------ checkpoint

    def state_tensors(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for k, m in enumerate(self.members):
            p = f"member{k}."
            for name, v in m.state_tensors().items():
                out[p + name] = np.asarray(v)
            for name, v in zip(_NORM, (m.x_norm.mean, m.x_norm.std, m.y_norm.mean, m.y_norm.std)):
                out[f"{p}norm.{name}"] = np.asarray(v, np.float64)
        return out

    def load_state_tensors(self, tensors: dict[str, np.ndarray]) -> None:
        n = self.hparams["n_members"]
        found = {key.split(".", 1)[0] for key in tensors}
        want = {f"member{k}" for k in range(n)}
        if found != want:
            raise ValueError(f"ensemble: checkpoint holds {sorted(found)}, expected {sorted(want)}")
        self.members = []
        for k in range(n):
            p = f"member{k}."
            sub = {key[len(p):]: v for key, v in tensors.items() if key.startswith(p)}
            norm = {name: np.asarray(sub.pop(f"norm.{name}"), np.float64) for name in _NORM}
            m = self._new_member()
            m.n_in, m.n_out = self.n_in, self.n_out
            m.inputs, m.targets, m.units = list(self.inputs), list(self.targets), dict(self.units)
            m.x_norm, m.y_norm = ZScore(norm["x_mean"], norm["x_std"]), ZScore(norm["y_mean"], norm["y_std"])
            m.seed = self.seed + k
            members_hist = self.history.get("members") if isinstance(self.history, dict) else None
            if isinstance(members_hist, list) and k < len(members_hist):
                m.history = dict(members_hist[k])
            m.load_state_tensors(sub)
            self.members.append(m)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "members": [m.describe() for m in self.members]}


class EnsembleStreamer(Streamer):
    """Steps every member's streamer on the same sample and averages their estimates."""

    def __init__(self, streamers: list[Streamer]):
        self.streamers = streamers

    def reset(self) -> None:
        for s in self.streamers:
            s.reset()

    def step(self, x: np.ndarray) -> np.ndarray:
        return np.mean([s.step(x) for s in self.streamers], axis=0)


def fit_ensembles(jobs: list[tuple[Ensemble, dict[str, Any]]]) -> None:
    """Fit several ensembles (e.g. one per input set, on the same episodes) with ALL their members trained as one
    batched network (learn.models.tcn.train_tcn_group): member k of an ensemble fitted with seed s is the member
    `Ensemble.fit` would train alone with seed s + k (its initial weights, batch order, Adam state and early
    stopping), up to float summation order. jobs: (ensemble, fit keyword arguments: xs, ys, valid, seed, inputs,
    targets, units). Members of kind tcn only; every ensemble's members share the training settings and the number
    of training examples."""
    from learn.models.tcn import TCNCompensator, fit_tcn_group

    members, zdata, seeds, owner = [], [], [], []
    for ens, kw in jobs:
        if ens.hparams["member"] != "tcn":
            raise ValueError(f"fit_ensembles: batched training needs tcn members, got {ens.hparams['member']!r}")
        ens.members = []
        for k in range(ens.hparams["n_members"]):
            m = ens._new_member()
            assert isinstance(m, TCNCompensator)
            zdata.append(m.fit_setup(kw["xs"], kw["ys"], kw.get("valid"), inputs=kw.get("inputs", ()),
                                     targets=kw.get("targets", ()), units=kw.get("units")))
            members.append(m)
            seeds.append(int(kw.get("seed", 0)) + k)
            owner.append(ens)
    fit_tcn_group(members, zdata, seeds)
    for m, ens in zip(members, owner):
        ens.members.append(m)
    for ens, kw in jobs:
        ens._finish(int(kw.get("seed", 0)))

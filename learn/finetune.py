"""Fine-tuning a compensator pre-trained on piezotwin data on a real recording (sim-to-real).

Input mapping (simulated channel <-> real channel), explicit and recorded in every checkpoint:
  1. rate: the real recording is resampled to the checkpoint's sample rate (moving average over one
     output period, then linear interpolation onto a uniform clock), so that a temporal model sees
     the same seconds of history it was trained on.
  2. transform ``log``: x = ln(reading). The simulated input is ln(resistance_measured / ohm), the real
     one ln(raw board reading) (the Lupasic board reads higher = more resistance). A power law
     G ~ p^n makes ln R ~ a - n ln F, so an unknown gain between raw counts and ohms is a pure offset
     in x, and the exponent mismatch a scale.
  3. input z-score over the real fine-tuning runs pooled (not per recording: a per-recording z-score
     would depend on how much of the run is unloaded and on its peak force, 2 N vs 45 N in the
     Lupasic runs, and would erase the absolute level that says which force it is). This replaces the
     simulator's statistics and needs inputs only, no labels (it is also the "zero-shot, restandardised"
     baseline).

Freeze policy (``head``, the default): the feature layers are frozen (TCN: the input 1x1 conv and
the dilated causal convolutions; MLP: every layer but the last; GRU/LSTM: the recurrent layers); they
hold the temporal dynamics (creep and loading-history memory) learned from plenty of simulated data.
Retrained: the output head (TCN: output conv + the linear skip path from the input; MLP/RNN: the last
dense layer) and a learnable affine of the normalised input (scale a, shift b per channel, started at
1, 0 after the re-standardisation of step 3), folded back into the checkpoint's input z-score when
saved. With one to a few real runs (a few thousand samples) this is tens of parameters instead of
thousands. ``none`` retrains every layer (same small learning rate), for comparison.

Methods (``method``): ``plain`` trains the policy's parameters from the pre-trained weights; ``l2sp`` adds
L2-SP's penalty alpha/2 ||w - w0||^2 over the retrained pre-trained weights w0 (and beta/2 ||(a - 1, b)||^2 on the
new input affine) to the training loss (Li, Grandvalet & Davoine 2018, ICML, "Explicit inductive bias for transfer
learning with convolutional networks", eq. of L2-SP); ``lpft`` first fits the head (policy ``head``, early stopped),
then every layer of the policy from there (Kumar et al. 2022, ICLR, "Fine-tuning can distort pretrained features
and underperform out-of-distribution": linear probing, then fine-tuning). Eighth round of issue 15 (CHANGELOG).
``shrink_perturb`` scales every pre-trained weight by SP_SHRINK and adds SP_NOISE times a fresh initialisation of its
layer before training as ``plain`` (Ash & Adams 2020, NeurIPS, "On warm-starting neural network training": a warm
start that fits its new data no better than a cold one, as pike1 -> pike2's fine-tuning with 4 and 14 runs did).

Early stopping uses held-out real data: whole runs (`split_runs`), or, in `piezotwin sim2real`, the last
loaded presses of each training run (`split_tail`: the same sensor, cut between presses). The pre-trained weights
are the first candidate (fine-tuning that never improves on them returns them).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from learn.data import Sequence
from learn.models.base import Compensator, make_model
from learn.normalize import ZScore
from sensors.data.resample import PART_SEP, key_matches, resample, resample_parts

__all__ = [
    "FINETUNE_METHODS",
    "FREEZE_POLICIES",
    "L2SP_ALPHA",
    "L2SP_BETA",
    "LOADED_PRESS_FRACTION",
    "TAIL_BY",
    "VALID_TAIL_FRACTION",
    "InputMap",
    "RealSplit",
    "apply_map",
    "finetune",
    "head_parameter_names",
    "l2sp_penalty",
    "load_recording",
    "resample",
    "restandardise",
    "split_runs",
    "split_tail",
    "train_from_scratch",
]

FREEZE_POLICIES = ("head", "none")
FINETUNE_METHODS = ("plain", "l2sp", "lpft", "shrink_perturb")
# estimates (not from the paper, which sweeps both): shrink-and-perturb's factor on the pre-trained weights and the
# scale of the fresh initialisation added to them (`_shrink_perturb`)
SP_SHRINK = 0.5
SP_NOISE = 0.1
# estimate: alpha 0.1 and beta 0.01 are the values Li et al. (2018) settled on for L2-SP (chosen there by cross-validation
# over 1e-3 ... 1 on image tasks, loss = mean per sample, as our MSE); taken as given, never tuned on these data
L2SP_ALPHA = 0.1
L2SP_BETA = 0.01
TRANSFORMS = ("log", "none")
# "log_headroom:<FS>": x = ln(FS - reading), for a divider whose reading rises with force toward its full scale FS
# (the reference resistor on the ADC side, sensors.chain_fit "low"): FS - reading = FS R / (R + r_ref), the same
# form as a "high" divider's reading, so x follows ln R as ln(reading) does there (learn.sim2real.input_transform)
HEADROOM = "log_headroom:"


def _headroom_fs(transform: str) -> float | None:
    if not transform.startswith(HEADROOM):
        return None
    try:
        fs = float(transform[len(HEADROOM):])
    except ValueError:
        fs = float("nan")
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"input transform {transform!r}: the full scale after '{HEADROOM}' must be a positive number")
    return fs


@dataclass
class InputMap:
    """How a recording's input channel becomes the model's input (see the module docstring)."""

    transform: str = "log"
    rate_hz: float | None = None  # resample to this rate (the checkpoint's); None: keep

    def __post_init__(self):
        if self.transform not in TRANSFORMS and _headroom_fs(self.transform) is None:
            raise ValueError(f"input transform must be one of {', '.join(TRANSFORMS)} or {HEADROOM}<full scale>; "
                             f"got {self.transform!r}")

    def to_json(self) -> dict[str, Any]:
        return {"transform": self.transform, "rate_hz": self.rate_hz}

    def describe(self) -> str:
        fs = _headroom_fs(self.transform)
        t = "x = ln(reading)" if self.transform == "log" else f"x = ln({fs:g} - reading)" if fs else "x = reading"
        r = f", resampled to {self.rate_hz:g} Hz" if self.rate_hz else ""
        return t + r


def forward_transform(x: np.ndarray, transform: str) -> np.ndarray:
    x = np.asarray(x, np.float64)
    if transform == "log":
        return np.log(np.maximum(x, 1e-12))
    fs = _headroom_fs(transform)
    if fs is not None:  # a reading at its full scale (saturated) keeps 1e-4 of it: no -27 outlier from ln(0)
        return np.log(np.maximum(fs - x, 1e-4 * fs))
    return x


def inverse_transform(x: np.ndarray, transform: str) -> np.ndarray:
    """The reading back from the model's input x (forward_transform's inverse)."""
    x = np.asarray(x, np.float64)
    if transform == "log":
        return np.exp(x)
    fs = _headroom_fs(transform)
    return fs - np.exp(x) if fs is not None else x


def load_recording(path: str | Path, inputs: Seq[str], targets: Seq[str], *, rate_hz: float | None = None,
                   episodes: Seq[str] | None = None) -> list[Sequence]:
    """Episodes of one recording file (or a dataset folder) as Sequences in physical units, optionally
    resampled to ``rate_hz``; ``meta['key']`` is the episode id."""
    from sensors.data.column_import import FORCE_TO_N
    from sensors.data.manifest import shard_files
    from sensors.data.recording import Recording, split_column

    path = Path(path)
    files = [path] if path.is_file() else shard_files(path)
    out: list[Sequence] = []
    for f in files:
        with Recording(f) as rec:
            for ep in rec.episode_ids:
                if episodes is not None and ep not in episodes:
                    continue
                def flat(c):  # a channel, or one column of it as "name[k]"
                    a = np.asarray(rec.read_column(ep, c), np.float64)
                    return a.reshape(len(a), -1)

                try:
                    x = np.concatenate([flat(c) for c in inputs], axis=1)
                    y = np.concatenate([flat(c) for c in targets], axis=1)
                except KeyError as exc:
                    raise ValueError(str(exc.args[0])) from None
                t = np.asarray(rec.read(ep, "time"), np.float64)
                parts = [(t, [x, y])]
                if rate_hz:
                    try:  # dropped samples (NaN) bridged up to MAX_GAP_S; cut at longer stretches (parts EP@k)
                        parts = resample_parts(t, [x, y], rate_hz)
                    except ValueError as exc:
                        raise ValueError(f"{f}: episode {ep}: {exc}") from None
                units = {c: rec.units(ep, split_column(c)[0]) for c in [*inputs, *targets]}
                scale = np.ones(len(targets))
                for j, c in enumerate(targets):  # a force label in another force unit (a capture's g) is read in N
                    if units[c] in FORCE_TO_N and units[c] != "N":
                        scale[j] = FORCE_TO_N[units[c]]
                        units[c] = "N"
                key = ep if len(files) == 1 else f"{f.stem}/{ep}"
                for k, (tk, (xk, yk)) in enumerate(parts):
                    meta = dict(rec.episode_attrs(ep))
                    meta["key"] = key if len(parts) == 1 else f"{key}{PART_SEP}{k + 1}"
                    out.append(Sequence(xk, yk * scale, list(inputs), list(targets), dict(units), meta, {"time": tk - tk[0]}))
    return out


def apply_map(seqs: Seq[Sequence], transform: str) -> list[Sequence]:
    """Copies of ``seqs`` with the input transform applied (x -> ln x for 'log')."""
    return [Sequence(forward_transform(s.x, transform), s.y, s.inputs, s.targets, s.units, s.meta, s.extra) for s in seqs]


# ---------------------------------------------------------------------------------------------- splits


@dataclass
class RealSplit:
    train: list[Sequence]
    valid: list[Sequence]
    test: list[Sequence]
    order: list[str] = field(default_factory=list)  # training runs in the order the learning curve adds them

    def keys(self) -> dict[str, list[str]]:
        return {k: [s.key for s in getattr(self, k)] for k in ("train", "valid", "test")}


def split_runs(seqs: Seq[Sequence], *, train_fraction: float | None, test_glob: str | None, seed: int,
               n_valid: int | None = None) -> RealSplit:
    """Split whole episodes (runs): test = episodes matching ``test_glob``, else a seeded
    (1 - train_fraction) share; of the rest (the fine-tuning pool; a train_fraction share of it when a
    glob fixes the test runs) ``n_valid`` runs (default max(1, round(pool / 4))) hold out for early
    stopping, the others train. Raises ValueError when a part would be empty."""
    seqs = sorted(seqs, key=lambda s: s.key)
    n = len(seqs)
    if n < 3:
        raise ValueError(f"need at least 3 episodes (runs) to split train/valid/test by run; the recording has {n}")
    rng = np.random.default_rng(int(seed))
    if test_glob:
        test = [s for s in seqs if key_matches(s.key, test_glob)]  # a part EP@k goes with its episode EP
        pool = [s for s in seqs if not key_matches(s.key, test_glob)]
        if not test:
            raise ValueError(f"--test-episodes {test_glob!r} matches no episode (episodes: {', '.join(s.key for s in seqs[:4])}, ...)")
        frac = 1.0 if train_fraction is None else train_fraction
        pool = [pool[i] for i in rng.permutation(len(pool))]
        pool = pool[: max(2, int(round(frac * len(pool))))] if pool else pool
    else:
        frac = 0.5 if train_fraction is None else train_fraction
        perm = [seqs[i] for i in rng.permutation(n)]
        n_pool = min(n - 1, max(2, int(round(frac * n))))
        pool, test = perm[:n_pool], perm[n_pool:]
    if len(pool) < 2:
        raise ValueError(f"the fine-tuning part has {len(pool)} run(s); needs 2 (one trains, one stops early)")
    nv = max(1, int(round(len(pool) / 4))) if n_valid is None else int(n_valid)
    nv = min(nv, len(pool) - 1)
    valid, train = pool[:nv], pool[nv:]
    return RealSplit(sorted(train, key=lambda s: s.key), sorted(valid, key=lambda s: s.key),
                     sorted(test, key=lambda s: s.key), order=[s.key for s in train])


VALID_TAIL_FRACTION = 0.25  # estimate: a quarter of each run's loaded presses stops early; the rest (3/4) trains
# a press is "loaded" when its peak reaches this share of the sensor's full scale: the same 10 % that
# sensors.chain_fit.presses_of's callers use to find a press in a run (there of the run's own peak), here of the
# sensor's range, so a run's 0.2 N touches on a 0-45 N sensor are not its validation presses (round 11, CHANGELOG)
LOADED_PRESS_FRACTION = 0.1
TAIL_BY = ("presses", "samples")


def split_tail(seqs: Seq[Sequence], frac: float = VALID_TAIL_FRACTION, *, full_scale_n: float | None = None,
               by: str = "presses") -> tuple[list[Sequence], list[Sequence]]:
    """Each run cut in time into (head, tail): the tail (its last presses) is the validation data for early
    stopping, the head trains. Validation then measures the sensor being calibrated, never another series or cover
    (with a whole run of another cover as validation, early stopping chose the weights that suited that cover).

    ``by="presses"`` (round 11): the tail holds the last k = ceil(frac x n) of the run's n loaded presses (peak >=
    LOADED_PRESS_FRACTION x ``full_scale_n``; None: the largest force in ``seqs``), k <= n - 1, cut in the middle of
    the release before the first of them; the head keeps everything before (smaller presses included). A run with
    fewer than two loaded presses gives no tail (all of it trains; its tail is left out of the returned list). If
    no run gives a tail, every press detected in a run counts as loaded. ``by="samples"`` (rounds 4-10): the cut in
    the release nearest to (1 - frac) of the run's samples (a run of fewer than two presses: at that sample), which
    can leave a run whose presses lie early a long tail of one small press. Presses: sensors.chain_fit.presses_of
    at 10 % of the run's peak force."""
    from sensors.chain_fit import presses_of

    if not 0.0 < frac < 1.0:
        raise ValueError(f"validation tail fraction must lie in (0, 1); got {frac}")
    if by not in TAIL_BY:
        raise ValueError(f"tail by must be one of {', '.join(TAIL_BY)}; got {by!r}")

    def part(s, a, b, tag):
        n = len(s)
        return Sequence(s.x[a:b], s.y[a:b], s.inputs, s.targets, s.units, {**s.meta, "key": f"{s.key}[{tag}]"},
                        {k: v[a:b] for k, v in s.extra.items() if len(v) == n})

    found = [presses_of(s.y[:, 0], max(0.1 * float(s.y[:, 0].max()), 1e-9)) for s in seqs]
    if by == "samples":
        cuts = []
        for s, pr in zip(seqs, found):
            n = len(s)
            want = (1.0 - frac) * n
            gaps = [(a.stop + b.start) // 2 for a, b in zip(pr[:-1], pr[1:])]
            cut = min(gaps, key=lambda g: abs(g - want)) if gaps else int(round(want))
            cuts.append(int(min(max(cut, 1), n - 1)))
    else:
        fs = float(full_scale_n) if full_scale_n is not None else max(float(s.y[:, 0].max()) for s in seqs)
        if not np.isfinite(fs) or fs <= 0.0:
            raise ValueError(f"full scale must be a positive finite force in N; got {full_scale_n}")

        def cuts_at(thr: float) -> list[int | None]:
            out = []
            for s, pr in zip(seqs, found):
                f = s.y[:, 0]
                loaded = [i for i, sl in enumerate(pr) if float(f[sl].max()) >= thr]
                if len(loaded) < 2:
                    out.append(None)
                    continue
                k = min(int(np.ceil(frac * len(loaded) - 1e-9)), len(loaded) - 1)
                first = loaded[-k]
                out.append(int((pr[first - 1].stop + pr[first].start) // 2))  # first >= 1: a loaded press precedes it
            return out

        cuts = cuts_at(LOADED_PRESS_FRACTION * fs)
        if all(c is None for c in cuts):
            cuts = cuts_at(0.0)
    heads, tails = [], []
    for s, cut in zip(seqs, cuts):
        if cut is None:
            heads.append(part(s, 0, len(s), "head"))
            continue
        heads.append(part(s, 0, cut, "head"))
        tails.append(part(s, cut, len(s), "tail"))
    return heads, tails


# ---------------------------------------------------------------------------------------------- freezing


def head_parameter_names(comp: Compensator) -> list[str]:
    """Names (in comp.net) of the parameters the ``head`` policy retrains."""
    net = comp.net
    names = [n for n, _ in net.named_parameters()]
    if comp.kind == "tcn":
        return [n for n in names if n.startswith(("out.", "skip."))]
    if comp.kind in ("gru", "lstm"):
        return [n for n in names if n.startswith("head.")]
    lin = [n for n, m in net.named_modules() if isinstance(m, nn.Linear)]
    if not lin:
        raise ValueError(f"{comp.kind}: no layer to retrain")
    return [n for n in names if n.startswith(lin[-1] + ".")]


class _InputAffine(nn.Module):
    """z' = a z + b on the last axis, in front of a net (a, b per input channel)."""

    def __init__(self, net: nn.Module, n_in: int):
        super().__init__()
        self.net = net
        self.a = nn.Parameter(torch.ones(n_in))
        self.b = nn.Parameter(torch.zeros(n_in))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x * self.a + self.b)


def restandardise(comp: Compensator, seqs: Seq[Sequence]) -> Compensator:
    """A copy whose input z-score comes from ``seqs`` (mapped inputs pooled): label-free adaptation."""
    c = copy.deepcopy(comp)
    c.x_norm = ZScore.fit([s.x for s in seqs])
    return c


def l2sp_penalty(module: nn.Module, alpha: float, beta: float = 0.0, new: Seq[str] = ()) -> Callable[[], torch.Tensor]:
    """L2-SP (Li, Grandvalet & Davoine 2018): alpha/2 sum ||w - w0||^2 over the trainable parameters of ``module`` as
    they are now (w0, the anchor: the pre-trained weights), except those named in ``new``, which get beta/2 ||w -
    w0||^2 toward their starting values (the paper's beta term on a new layer; ours, the input affine, starts at
    the identity). Returns the penalty as a function of the current weights."""
    named = [(n, p) for n, p in module.named_parameters() if p.requires_grad]
    anchor = [(p, p.detach().clone(), float(beta if n in set(new) else alpha)) for n, p in named]

    def penalty() -> torch.Tensor:
        return sum(0.5 * w * torch.sum((p - p0) ** 2) for p, p0, w in anchor if w > 0.0) + torch.zeros(())

    return penalty


def _torch_only(comp: Compensator) -> None:
    if getattr(comp, "net", None) is None or not hasattr(comp, "_examples"):
        raise ValueError(f"model {comp.kind!r} has no neural layers to fine-tune (use a tcn, mlp, gru or lstm checkpoint)")


def finetune(comp: Compensator, train: Seq[Sequence], valid: Seq[Sequence], *, policy: str = "head",
             lr: float = 3e-4, max_epochs: int = 300, patience: int = 30, batch_size: int | None = None,
             seed: int = 0, progress: bool = False, norm: str = "real",
             rehearsal: Seq[Sequence] = (), method: str = "plain", l2sp_alpha: float = L2SP_ALPHA,
             l2sp_beta: float = L2SP_BETA,
             on_epoch: Callable[[int, Compensator], None] | None = None) -> tuple[Compensator, dict[str, Any]]:
    """Fine-tune a copy of ``comp`` on mapped real runs; returns (compensator, info). See the module docstring.

    ``norm``: ``real`` re-estimates the input z-score on the real training runs (step 3 of the input map);
    ``checkpoint`` keeps the pre-trained one (right when the simulated input is already in the real
    readout's units, as after `piezotwin fit`: then the pre-trained z-score is a fixed physical map and
    re-estimating it on one or two runs, whose force range sets their statistics, moves it by a
    subset-dependent amount); the learnable input affine absorbs a gain/offset either way.
    ``rehearsal``: simulated episodes (same input map) added to the training examples (the pre-training
    distribution kept in view while adapting: limits forgetting when the real runs are few); early
    stopping still on the real valid runs only.
    ``method``: ``plain``, ``l2sp`` (``l2sp_alpha``, ``l2sp_beta``) or ``lpft`` (see the module docstring).
    ``on_epoch``: a probe called as on_epoch(epoch, compensator) before training (epoch -1) and after each epoch,
    with a copy of the net as it stands, its input affine folded (learn.train.train_model's ``on_epoch``; plain and
    l2sp only). None: nothing runs."""
    if norm not in ("real", "checkpoint"):
        raise ValueError(f"norm must be 'real' or 'checkpoint'; got {norm!r}")
    if method not in FINETUNE_METHODS:
        raise ValueError(f"fine-tuning method must be one of {', '.join(FINETUNE_METHODS)}; got {method!r}")
    if method == "lpft" and on_epoch is not None:
        raise ValueError("on_epoch: plain and l2sp only (lpft runs two stages)")
    if method == "lpft":
        kw = dict(lr=lr, max_epochs=max_epochs, patience=patience, batch_size=batch_size, seed=seed, rehearsal=rehearsal)
        lp, lp_info = finetune(comp, train, valid, policy="head", norm=norm, **kw)
        # stage 2 starts from the probed net (its input affine folded into the z-score, which it keeps)
        c, info = finetune(lp, train, valid, policy=policy, norm="checkpoint", **kw)
        info.update(method="lpft", valid_mse_z_before=lp_info["valid_mse_z_before"],
                    linear_probe={k: lp_info[k] for k in ("epochs", "best_epoch", "best_loss", "n_trainable")})
        c.history = {k: v for k, v in info.items() if k not in ("train_loss", "valid_loss")}
        return c, info
    from learn.train import TrainConfig, train_model

    if policy not in FREEZE_POLICIES:
        raise ValueError(f"freeze policy must be one of {', '.join(FREEZE_POLICIES)}; got {policy!r}")
    _torch_only(comp)
    c = restandardise(comp, train) if norm == "real" else copy.deepcopy(comp)
    if method == "shrink_perturb":
        _shrink_perturb(c.net, SP_SHRINK, SP_NOISE, seed)
    head = set(head_parameter_names(c))
    frozen = []
    for n, p in c.net.named_parameters():
        train_it = policy == "none" or n in head
        p.requires_grad_(train_it)
        if not train_it:
            frozen.append(n)
    wrapped = _InputAffine(c.net, c.n_in)
    zx = [c.x_norm.apply(s.x) for s in [*train, *rehearsal]]
    zy = [c.y_norm.apply(s.y) for s in [*train, *rehearsal]]
    vx = [c.x_norm.apply(s.x) for s in valid]
    vy = [c.y_norm.apply(s.y) for s in valid]
    tr = c._examples(zx, zy, True)
    va = c._examples(vx, vy, False)
    with torch.no_grad():
        before = torch.nn.functional.mse_loss(wrapped(va[0]), va[1]).item()
    cfg = TrainConfig(lr=lr, batch_size=int(batch_size or c.hparams.get("batch_size", 32)), max_epochs=max_epochs,
                      patience=patience, grad_clip=1.0, seed=seed)
    # the pre-trained weights stay a candidate: no step that worsens the validation loss is kept
    pen = l2sp_penalty(wrapped, float(l2sp_alpha), float(l2sp_beta), new=("a", "b")) if method == "l2sp" else None
    probe = None
    if on_epoch is not None:
        def probe(epoch: int, _net: nn.Module) -> None:
            snap = copy.deepcopy(c)
            _fold_affine(snap, wrapped)
            snap.net.eval()
            on_epoch(epoch, snap)
    hist = train_model(wrapped, tr, va, cfg, progress=progress, description=f"finetune[{policy}]", keep_initial=True,
                       penalty=pen, on_epoch=probe)
    a = wrapped.a.detach().double().numpy()
    b = wrapped.b.detach().double().numpy()
    _fold_affine(c, wrapped)
    for p in c.net.parameters():
        p.requires_grad_(True)
    c.net.eval()
    n_trainable = sum(p.numel() for n, p in c.net.named_parameters() if n not in frozen) + 2 * c.n_in
    info = {"policy": policy, "frozen": frozen, "trained": sorted(set(n for n, _ in c.net.named_parameters()) - set(frozen)) + ["input affine a, b"],
            "n_trainable": int(n_trainable), "n_parameters": int(sum(p.numel() for p in c.net.parameters())),
            "lr": lr, "norm": norm, "method": method,
            **({"l2sp_alpha": float(l2sp_alpha), "l2sp_beta": float(l2sp_beta)} if method == "l2sp" else {}),
            **({"sp_shrink": SP_SHRINK, "sp_noise": SP_NOISE} if method == "shrink_perturb" else {}), "n_rehearsal_episodes": len(rehearsal), "valid_mse_z_before": before, "input_affine": {"a": a.tolist(), "b": b.tolist()},
            "n_train_runs": len(train), "n_valid_runs": len(valid), **hist.to_json()}
    c.history = {k: v for k, v in info.items() if k not in ("train_loss", "valid_loss")}
    return c, info


def _shrink_perturb(net: nn.Module, shrink: float, noise: float, seed: int) -> None:
    """In place: every parameter w <- shrink w + noise w0, w0 a fresh initialisation of its layer (each module's own
    `reset_parameters`, drawn from torch's generator seeded with `seed`). Ash & Adams 2020 (NeurIPS), shrink-perturb."""
    fresh = copy.deepcopy(net)
    torch.manual_seed(seed)
    for m in fresh.modules():
        if hasattr(m, "reset_parameters"):
            m.reset_parameters()
    with torch.no_grad():
        for w, w0 in zip(net.parameters(), fresh.parameters()):
            w.mul_(shrink).add_(noise * w0)


def _fold_affine(c: Compensator, wrapped: _InputAffine) -> None:
    """Fold the input affine z' = a (x - m) / s + b of ``wrapped`` into ``c``'s z-score: mean m - b s / a, std s / a."""
    a = wrapped.a.detach().double().numpy()
    b = wrapped.b.detach().double().numpy()
    m, s = c.x_norm.mean, c.x_norm.std
    c.x_norm = ZScore(m - b * s / a, s / a)


def train_from_scratch(kind: str, hparams: dict[str, Any], train: Seq[Sequence], valid: Seq[Sequence], *,
                       seed: int = 0, progress: bool = False, **overrides: Any) -> Compensator:
    """The same architecture, fresh weights, trained on the real runs only (its own z-score)."""
    hp = {**hparams, **overrides}
    comp = make_model(kind, **hp)
    comp.fit([s.x for s in train], [s.y for s in train], valid=([s.x for s in valid], [s.y for s in valid]),
             seed=seed, progress=progress, inputs=train[0].inputs, targets=train[0].targets, units=train[0].units)
    return comp


def rmse_on(comp: Compensator, seqs: Seq[Sequence]) -> float:
    est = np.concatenate([comp.predict(s.x)[:, 0] for s in seqs])
    ref = np.concatenate([s.y[:, 0] for s in seqs])
    return float(np.sqrt(np.mean((est - ref) ** 2)))


def per_run(comp: Compensator, seqs: Seq[Sequence], fn: Callable[[np.ndarray, np.ndarray], float]) -> dict[str, float]:
    return {s.key: fn(s.y[:, 0], comp.predict(s.x)[:, 0]) for s in seqs}

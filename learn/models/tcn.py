"""Our model: a causal temporal convolution net (TCN) over the resistance history.

Why it fits this sensor: what separates loading from unloading at equal resistance is mostly a linear
causal filter (the 4th-order 10 Hz Butterworth delays the signal ~40 ms) plus viscoelastic memory,
followed by a static nonlinearity (tunneling). Dilated causal convolutions see 1.27 s of history
(receptive field 1 + (k-1) sum(d) = 127 samples at k=3, d=1..32) at a cost that does not grow with it,
train on whole chunks (one forward gives every output of a chunk), and stream in O(1) per sample:
each layer keeps a ring buffer of its last (k-1) d + 1 inputs, so no window is recomputed.

    h_0 = W_in x                                (1x1 conv)
    h_{l+1} = h_l + SiLU(conv_{k, d_l}(h_l))     (causal, valid, residual)
    y = W_out h_L + W_skip x                     (1x1 convs; the skip is a linear path from input)

``log_inputs`` (indices of input channels, default none): ln x of those channels joins the inputs (z-scored
with the training statistics, kept as buffers of the net, so checkpoints and stream() need nothing else).
For a resistance that spans a decade or more (the fabric stacks) the log is the natural scale of the
contact law (R_c ~ F^-1/3 .. F^-1/2) and a z-scored R alone crowds the high-force end.

``play_widths`` (fractions, default none; needs ``log_inputs``): a Prandtl-Ishlinskii bank of play
(backlash) operators on u = the z-scored ln x of the first log channel, the classic inverse-hysteresis
compensator's memory (Kuhnen 2003, "Modeling, identification and compensation of complex hysteretic
nonlinearities"; Brokate & Sprekels 1996, ch. 2). Width j is r_j = play_widths[j] * (max u - min u over the
training inputs); the operator p_j(t) = min(u + r_j, max(u - r_j, p_j(t-1))), p_j(0) = u(0), and the net reads
the normalised gap g_j = (p_j - u) / r_j in [-1, 1]: the branch direction (small widths) and where the last
turning points lie (large widths), with the wiping-out (return-point) memory a receptive field of finite
length does not have. Computed on whole sequences before the convolutions (it is recursive) and stepped in
stream(); the widths live in the checkpoint as the buffer ``play_r``.

``diff_loss_weight`` (lambda, default 0: the plain MSE) and ``diff_loss_lag`` (k samples, default 10): derivative
matching (Sobolev training; Czarnecki et al., NeurIPS 2017, "Sobolev Training for Neural Networks"): the loss is
MSE(y_hat, y) + lambda * MSE(D_k y_hat, D_k y), D_k x_t = x_t - x_{t-k}, differences taken only between two outputs
of one training chunk (consecutive samples of one episode, every one a valid causal output), L - k per chunk of L.
Where the label is flat (a hold) this penalises any change of the estimate over k samples: drift, without a hold
detector. Training and the validation loss that stops early both use it (`diff_matched_mse`).
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch
from torch import nn

from learn.models.base import Streamer, register
from learn.models.neural import TRAIN_DEFAULTS, TorchCompensator, _f32
from learn.train import TrainConfig, TrainHistory

__all__ = ["CausalTCN", "TCNCompensator", "diff_matched_mse", "fit_tcn_group", "play_gaps", "train_tcn_group"]


def diff_matched_mse(pred: torch.Tensor, y: torch.Tensor, weight: float, lag: int, *, dim: int = 1,
                     reduction: str = "mean") -> torch.Tensor:
    """Sobolev training's loss on chunks (Czarnecki et al. 2017, "Sobolev Training for Neural Networks"):
    mean(e^2) + weight * mean((D_lag e)^2), e = pred - y, D_lag e_t = e_t - e_{t-lag} along ``dim`` (the time axis
    of one chunk's outputs; D_lag pred - D_lag y = D_lag e). reduction "sum": a sum whose mean per element of e is
    that mean (the difference term counted L / (L - lag) times per difference), as learn.train.evaluate divides."""
    e = pred - y
    L = e.shape[dim]
    de = _diffs(e, lag, dim)
    if reduction == "mean":
        return (e * e).mean() + weight * (de * de).mean()
    if reduction == "sum":
        return (e * e).sum() + weight * (de * de).sum() * (L / (L - lag))
    raise ValueError(f"reduction must be mean or sum, got {reduction!r}")


def play_gaps(u: np.ndarray, r: np.ndarray, p0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Play operators of widths r [m] (> 0) on the series u [T]: the gaps (p - u) / r [T, m] and the last
    state p [m]. p starts at p0 (default u[0]: the input has rested at its first value)."""
    u = np.asarray(u, np.float64).reshape(-1)
    r = np.asarray(r, np.float64).reshape(-1)
    p = np.full(len(r), u[0]) if p0 is None else np.array(p0, np.float64)
    out = np.empty((len(u), len(r)))
    for t, ut in enumerate(u):
        p = np.minimum(ut + r, np.maximum(ut - r, p))
        out[t] = p
    return (out - u[:, None]) / r, p


class LogFeatures(nn.Module):
    """Normalised x [..., n_in] -> [..., n_in + len(idx)]: x, then z-scored ln of the raw channels ``idx``.
    Buffers: the x statistics (to undo the z-score) and those of ln x."""

    def __init__(self, n_in: int, idx: list[int]):
        super().__init__()
        self.idx = [int(i) for i in idx]
        for name, n in (("x_mean", n_in), ("x_std", n_in), ("l_mean", len(self.idx)), ("l_std", len(self.idx))):
            self.register_buffer(name, torch.ones(n, dtype=torch.float32))

    def raw_log(self, z: np.ndarray | torch.Tensor):
        """ln of the raw channels idx from normalised z (numpy or torch), floored at 1e-12."""
        if isinstance(z, torch.Tensor):
            raw = z[..., self.idx] * self.x_std[self.idx] + self.x_mean[self.idx]
            return torch.log(torch.clamp(raw, min=1e-12))
        g = lambda t: t.detach().double().numpy()
        raw = z[..., self.idx] * g(self.x_std)[self.idx] + g(self.x_mean)[self.idx]
        return np.log(np.maximum(raw, 1e-12))

    def set_stats(self, x_mean, x_std, zx: list[np.ndarray]) -> None:
        self.x_mean.copy_(torch.as_tensor(np.asarray(x_mean), dtype=torch.float32))
        self.x_std.copy_(torch.as_tensor(np.asarray(x_std), dtype=torch.float32))
        lg = np.concatenate([self.raw_log(np.asarray(z, np.float64)) for z in zx])
        self.l_mean.copy_(torch.as_tensor(lg.mean(0), dtype=torch.float32))
        self.l_std.copy_(torch.as_tensor(np.maximum(lg.std(0), 1e-12), dtype=torch.float32))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return torch.cat([z, (self.raw_log(z) - self.l_mean) / self.l_std], dim=-1)

    def numpy(self, z: np.ndarray) -> np.ndarray:
        g = lambda t: t.detach().double().numpy()
        return np.concatenate([z, (self.raw_log(z) - g(self.l_mean)) / g(self.l_std)], axis=-1)


class CausalTCN(nn.Module):
    """[B, L, n_in] -> [B, L - rf + 1, n_out] (valid causal convolutions). With ``log_inputs`` the net
    first appends the z-scored ln of those raw input channels (LogFeatures)."""

    def __init__(self, n_in: int, n_out: int, channels: int, kernel: int, dilations: list[int],
                 log_inputs: list[int] | None = None, n_play: int = 0):
        super().__init__()
        if log_inputs:
            self.feat = LogFeatures(n_in, list(log_inputs))
            n_in = n_in + len(self.feat.idx)
        else:
            self.feat = None
        # play gaps arrive appended to the normalised inputs (computed outside: the operator is recursive)
        self.n_play = int(n_play)
        if self.n_play:  # only then: checkpoints of a TCN without play load as before
            self.register_buffer("play_r", torch.ones(self.n_play, dtype=torch.float32))
        n_in = n_in + self.n_play
        self.kernel, self.dilations = int(kernel), [int(d) for d in dilations]
        self.rf = 1 + (self.kernel - 1) * sum(self.dilations)
        self.inp = nn.Conv1d(n_in, channels, 1)
        self.convs = nn.ModuleList(nn.Conv1d(channels, channels, kernel, dilation=d) for d in self.dilations)
        self.out = nn.Conv1d(channels, n_out, 1)
        self.skip = nn.Conv1d(n_in, n_out, 1)

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """[B, L, n_in (+ n_play)] -> the convolutions' inputs [B, L, n_conv_in] (ln channels appended; no weights)."""
        if self.feat is not None:
            if self.n_play:
                g = x[..., x.shape[-1] - self.n_play :]
                x = torch.cat([self.feat(x[..., : x.shape[-1] - self.n_play]), g], dim=-1)
            else:
                x = self.feat(x)
        return x

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.features(x).transpose(1, 2)
        h = self.inp(x)
        for conv, d in zip(self.convs, self.dilations):
            h = h[..., d * (self.kernel - 1) :] + nn.functional.silu(conv(h))
        y = self.out(h) + self.skip(x[..., self.rf - 1 :])
        return y.transpose(1, 2)


@register("tcn")
class TCNCompensator(TorchCompensator):
    """Causal TCN (ours). Trained on chunks of ``chunk`` outputs (stride chunk/2) with the same Adam /
    early-stopping loop as the paper's models."""

    DEFAULTS = {**TRAIN_DEFAULTS, "channels": 32, "kernel": 3, "dilations": [1, 2, 4, 8, 16, 32],
                "chunk": 64, "batch_size": 16, "lr": 2e-3, "log_inputs": None, "play_widths": None,
                "residual_input": None, "diff_loss_weight": 0.0, "diff_loss_lag": 10}
    temporal = True

    # ``diff_loss_weight`` / ``diff_loss_lag``: derivative matching (module docstring); weight 0 is the plain MSE
    # (the very same code path as before). Lag 10 samples: 1 s at velostat's 10 Hz, the hold-drift metric's scale.

    def diff_loss(self) -> tuple[float, int]:
        """(weight, lag) of the derivative-matching term, checked."""
        w, k = float(self.hparams["diff_loss_weight"]), int(self.hparams["diff_loss_lag"])
        if not (np.isfinite(w) and w >= 0) or k < 1:
            raise ValueError(f"tcn: diff_loss_weight must be >= 0 and diff_loss_lag >= 1, got {w}, {k}")
        return w, k

    def loss_fn(self):
        w, k = self.diff_loss()
        if w == 0:
            return None
        return lambda pred, y, reduction="mean": diff_matched_mse(pred, y, w, k, dim=1, reduction=reduction)

    # ``residual_input`` (an input channel's name, default none): the net learns a correction to that input
    # (a static calibration's estimate in the targets' unit, e.g. the compensated paper chain's force): it trains
    # on y - x[residual_input] and its estimate is x[residual_input] + the net's output (predict and stream()).
    # One target only; the channel stays an input as well.

    def _residual_idx(self, inputs) -> int | None:
        name = self.hparams["residual_input"]
        if name is None:
            return None
        names = list(inputs) or [f"x{i}" for i in range(self.n_in)]
        if name not in names:
            raise ValueError(f"tcn: residual_input {name!r} is not an input channel ({names})")
        return names.index(name)

    def fit_setup(self, xs, ys, valid=None, *, inputs=(), targets=(), units=None):
        if self.hparams["residual_input"] is not None:
            xs = [np.asarray(x, np.float64).reshape(len(x), -1) for x in xs]
            self.n_in = xs[0].shape[1]
            j = self._residual_idx(inputs)
            ys = [np.asarray(y, np.float64).reshape(len(y), -1) for y in ys]
            if ys[0].shape[1] != 1:
                raise ValueError("tcn: residual_input needs one target")
            ys = [y - x[:, j : j + 1] for x, y in zip(xs, ys)]
            if valid is not None and len(valid[0]):
                vx = [np.asarray(x, np.float64).reshape(len(x), -1) for x in valid[0]]
                valid = (vx, [np.asarray(y, np.float64).reshape(len(y), -1) - x[:, j : j + 1]
                              for x, y in zip(vx, valid[1])])
        return super().fit_setup(xs, ys, valid, inputs=inputs, targets=targets, units=units)

    def predict(self, x):
        if isinstance(x, (list, tuple)):
            return [self.predict(v) for v in x]
        out = super().predict(x)
        j = self._residual_idx(self.inputs)
        if j is not None:
            out = out + np.asarray(x, np.float64).reshape(len(x), -1)[:, j : j + 1]
        return out

    @property
    def context(self) -> int:
        h = self.hparams
        return 1 + (int(h["kernel"]) - 1) * sum(int(d) for d in h["dilations"])

    def _build(self):
        h = self.hparams
        return CausalTCN(self.n_in, self.n_out, int(h["channels"]), int(h["kernel"]), list(h["dilations"]),
                         list(h["log_inputs"] or []), len(h["play_widths"] or []))

    def _play_u(self, z: np.ndarray) -> np.ndarray:
        """u: the z-scored ln of the first log channel (LogFeatures' statistics) of normalised inputs z [T, n_in]."""
        f = self.net.feat
        g = lambda t: t.detach().double().numpy()
        return (f.raw_log(np.asarray(z, np.float64)[:, :1 + max(f.idx)])[:, 0] - g(f.l_mean)[0]) / g(f.l_std)[0]

    def _augment(self, z: np.ndarray) -> np.ndarray:
        """Normalised inputs [T, n_in] -> [T, n_in + n_play] (the play gaps appended); unchanged without play."""
        if not self.net.n_play:
            return z
        gaps, _ = play_gaps(self._play_u(z), self.net.play_r.detach().double().numpy())
        return np.concatenate([z, gaps], axis=1)

    def _prepare(self, zx):
        idx = list(self.hparams["log_inputs"] or [])
        if not idx:
            if self.hparams["play_widths"]:
                raise ValueError("tcn: play_widths needs log_inputs (the play bank runs on the first log channel)")
            return
        bad = [i for i in idx if not 0 <= int(i) < self.n_in]
        if bad:
            raise ValueError(f"tcn: log_inputs {bad} outside the {self.n_in} input channels")
        lo = min(float((z * self.x_norm.std + self.x_norm.mean)[:, idx].min()) for z in zx)
        if lo <= 0:
            raise ValueError(f"tcn: log_inputs need positive inputs (minimum {lo:g})")
        self.net.feat.set_stats(self.x_norm.mean, self.x_norm.std, zx)
        w = [float(v) for v in (self.hparams["play_widths"] or [])]
        if w:
            if not all(np.isfinite(v) and 0 < v <= 1 for v in w):
                raise ValueError(f"tcn: play_widths must lie in (0, 1] (fractions of the training span), got {w}")
            u = np.concatenate([self._play_u(z) for z in zx])
            span = max(float(u.max() - u.min()), 1e-6)
            self.net.play_r.copy_(torch.as_tensor(np.asarray(w) * span, dtype=torch.float32))
    def _pad(self, z: np.ndarray) -> np.ndarray:
        return np.concatenate([np.repeat(z[:1], self.context - 1, axis=0), z], axis=0)

    def _examples(self, zx, zy, train):
        L = min(int(self.hparams["chunk"]), min(len(x) for x in zx))
        rf = self.context
        X, Y = [], []
        for x, y in zip(zx, zy):
            xp = self._pad(self._augment(x))
            starts = sorted(set(range(0, len(x) - L + 1, max(1, L // 2))) | {len(x) - L})
            for s in starts:
                X.append(xp[s : s + L + rf - 1])
                Y.append(y[s : s + L])
        return _f32(np.stack(X)), _f32(np.stack(Y))

    def _forward_seq(self, z):
        return self.net(_f32(self._pad(self._augment(z)))[None])[0].double().numpy()

    def _streamer(self) -> Streamer:
        return TCNStreamer(self)


class TCNStreamer(Streamer):
    """Per-layer ring buffers in numpy (float64): O(1) work per sample, equal to the batch forward."""

    def __init__(self, comp: TCNCompensator):
        net = comp.net
        g = lambda t: t.detach().double().numpy()
        self.xm, self.xs = comp.x_norm.mean, comp.x_norm.std
        self.feat = net.feat
        self.comp = comp
        self.play_r = g(net.play_r) if net.n_play else None
        self.ym, self.ys = comp.y_norm.mean, comp.y_norm.std
        self.w_in, self.b_in = g(net.inp.weight)[:, :, 0], g(net.inp.bias)
        self.k = net.kernel
        self.dil = net.dilations
        # conv weight [C, C, k]; tap j multiplies the input (k-1-j) d samples back -> one [C, k C] matrix
        self.w = [np.concatenate([g(c.weight)[:, :, j] for j in range(self.k)], axis=1) for c in net.convs]
        self.b = [g(c.bias) for c in net.convs]
        self.w_out, self.b_out = g(net.out.weight)[:, :, 0], g(net.out.bias)
        self.w_skip, self.b_skip = g(net.skip.weight)[:, :, 0], g(net.skip.bias)
        self.lens = [(self.k - 1) * d + 1 for d in self.dil]
        self.res = comp._residual_idx(comp.inputs)  # residual_input: its raw value is added to the estimate
        self.reset()

    def reset(self) -> None:
        self.bufs: list[np.ndarray] | None = None
        self.t = 0
        self.play_p: np.ndarray | None = None

    def step(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, np.float64).reshape(-1)
        z = (x - self.xm) / self.xs
        gaps = None
        if self.play_r is not None:
            gaps, self.play_p = play_gaps(self.comp._play_u(z[None]), self.play_r, self.play_p)
        if self.feat is not None:
            z = self.feat.numpy(z)
        if gaps is not None:
            z = np.concatenate([z, gaps[0]])
        h = self.w_in @ z + self.b_in
        first = self.bufs is None
        if first:
            self.bufs = [np.empty((n, len(h))) for n in self.lens]
        t = self.t
        for l, d in enumerate(self.dil):
            buf, n = self.bufs[l], self.lens[l]
            if first:  # the input has rested at its first value forever: constant history
                buf[:] = h
            else:
                buf[t % n] = h
            taps = buf[[(t - (self.k - 1 - j) * d) % n for j in range(self.k)]].reshape(-1)
            a = self.w[l] @ taps + self.b[l]
            h = h + a / (1.0 + np.exp(-a))
        self.t += 1
        y = self.w_out @ h + self.b_out + self.w_skip @ z + self.b_skip
        y = y * self.ys + self.ym
        return y if self.res is None else y + x[self.res]


# ---------------------------------------------------------------------------------------------------------------
# several TCNs trained as one batched (grouped-convolution) network


def _layers(net: CausalTCN) -> list[tuple[nn.Parameter, int]]:
    """(parameter, padded axis or -1) in the flat layout's order: the input-side weights pad their input channels."""
    out = [(net.inp.weight, 1), (net.inp.bias, -1)]
    for c in net.convs:
        out += [(c.weight, -1), (c.bias, -1)]
    return out + [(net.out.weight, -1), (net.out.bias, -1), (net.skip.weight, 1), (net.skip.bias, -1)]


def _diffs(e: torch.Tensor, lag: int, dim: int = -1) -> torch.Tensor:
    """e_t - e_{t-lag} along ``dim`` (the time axis of one chunk's L outputs): L - lag differences."""
    L = e.shape[dim]
    if not 1 <= lag < L:
        raise ValueError(f"tcn: diff_loss_lag {lag} needs 1 <= lag < the chunk's {L} outputs")
    return e.narrow(dim, lag, L - lag) - e.narrow(dim, 0, L - lag)


def train_tcn_group(nets: list[CausalTCN], trains: list[tuple[torch.Tensor, torch.Tensor]],
                    valids: list[tuple[torch.Tensor, torch.Tensor] | None], cfgs: list[TrainConfig],
                    device: str | None = None, diff_loss: tuple[float, int] = (0.0, 10)) -> list[TrainHistory]:
    """Train G TCNs of one architecture (their input channels may differ) as ONE network: each layer a grouped
    convolution over the members (groups = G), every member's weights in one flat buffer, so a step is one forward,
    one backward and one Adam update for all. Member g keeps what `learn.train.train_model` gives it alone: its
    initial weights (its net as built), its batch order (a generator seeded with cfgs[g].seed), its loss (the MSE of
    its own batch; the members' losses are summed, so no gradient crosses members), its gradient-norm clip, its Adam
    moments, and its early stopping on its own validation loss (best weights kept; a stopped member leaves the
    group). The members must share the number of training examples and every TrainConfig field but the seed (an
    ensemble's members on the same episodes). Equal to training them one after another up to float summation order
    (tests/test_learn_models.py). Inputs narrower than the widest member are padded with zero channels whose
    weights start and stay at zero (zero input: zero gradient, zero Adam step). ``diff_loss`` (weight, lag): every
    member's loss (training and validation) is `diff_matched_mse` on its own outputs, shared by the members; weight
    0 is the MSE as before. Leaves each net on the CPU with its best weights; returns each member's TrainHistory
    (seconds: the group's wall time)."""
    from learn.train import current_device, resolve_device

    G = len(nets)
    c0 = cfgs[0]
    same = lambda c: {**c.to_json(), "seed": 0}
    if any(same(c) != same(c0) for c in cfgs):
        raise ValueError("train_tcn_group: the members must share every training setting but the seed")
    arch = lambda n: (n.kernel, tuple(n.dilations), n.inp.out_channels, n.out.out_channels)
    if any(arch(n) != arch(nets[0]) for n in nets):
        raise ValueError("train_tcn_group: the members must share kernel, dilations, channels and outputs")
    N = len(trains[0][0])
    if any(len(t[0]) != N for t in trains):
        raise ValueError("train_tcn_group: the members must have as many training examples each")
    has_valid = [v is not None for v in valids]
    if any(h != has_valid[0] for h in has_valid) or (has_valid[0] and len({len(v[0]) for v in valids}) != 1):
        raise ValueError("train_tcn_group: validation examples for every member or none, as many each")
    dev = torch.device(resolve_device(c0.device) if c0.device is not None else current_device())
    k, dil, n_out = nets[0].kernel, nets[0].dilations, nets[0].out.out_channels
    rf = nets[0].rf
    dw, dk = float(diff_loss[0]), int(diff_loss[1])
    cin = [n.inp.in_channels for n in nets]
    cmax = max(cin)

    def unique(pairs):  # identical example tensors (members of one input set) stored once: [U, N, cmax, L]
        ux, uy, uid = [], [], []
        for net, (x, y) in pairs:
            with torch.no_grad():
                f = net.features(x.float())
            for j, (a, b) in enumerate(zip(ux, uy)):
                if a.shape[1] == f.shape[-1] and torch.equal(a[..., : f.shape[-1]], f) and torch.equal(b, y):
                    uid.append(j)
                    break
            else:
                uid.append(len(ux))
                ux.append(f)
                uy.append(y.float())
        X = torch.zeros(len(ux), len(ux[0]), cmax, ux[0].shape[1])
        for j, f in enumerate(ux):
            X[j, :, : f.shape[-1]] = f.transpose(1, 2)
        Y = torch.stack([y.transpose(1, 2) for y in uy])  # [U, N, n_out, L']
        return X.to(dev), Y.to(dev), torch.tensor(uid, device=dev)

    Xt, Yt, uid_t = unique(list(zip(nets, trains)))
    if has_valid[0]:
        Xv, Yv, uid_v = unique(list(zip(nets, valids)))
    # the flat buffer: per layer a block [G, *shape] (padded input channels), blocks one after another
    shapes, blocks = [], []
    for li, (p0, ax) in enumerate(_layers(nets[0])):
        shp = list(p0.shape)
        if ax >= 0:
            shp[ax] = cmax
        shapes.append(shp)
        rows = []
        for net in nets:
            w = torch.zeros(shp)
            p, _ = _layers(net)[li]
            w[tuple(slice(0, s) for s in p.shape)] = p.detach().float()
            rows.append(w.reshape(-1))
        blocks.append(torch.stack(rows))
    sizes = [math.prod(s) for s in shapes]

    def layout(rows: list[torch.Tensor]) -> torch.Tensor:
        return torch.cat([r.reshape(-1) for r in rows])

    flat = layout(blocks).to(dev)
    m1, m2 = torch.zeros_like(flat), torch.zeros_like(flat)
    live = list(range(G))  # member index of each row of the blocks

    def member_ids(n: int) -> torch.Tensor:
        return torch.cat([torch.arange(n, device=dev).repeat_interleave(sz) for sz in sizes])

    def views(buf: torch.Tensor, n: int) -> list[torch.Tensor]:
        out, o = [], 0
        for shp, sz in zip(shapes, sizes):
            out.append(buf[o : o + n * sz].view(n * shp[0], *shp[1:]))
            o += n * sz
        return out

    def rows_of(buf: torch.Tensor, n: int, keep: list[int]) -> torch.Tensor:
        out, o = [], 0
        for sz in sizes:
            out.append(buf[o : o + n * sz].view(n, sz)[keep].reshape(-1))
            o += n * sz
        return torch.cat(out)

    def forward(buf: torch.Tensor, n: int, x: torch.Tensor) -> torch.Tensor:
        """x [b, n * cmax, L] -> [b, n, n_out, L - rf + 1]."""
        W = views(buf, n)
        conv = torch.nn.functional.conv1d
        h = conv(x, W[0], W[1], groups=n)
        for li, d in enumerate(dil):
            h = h[..., d * (k - 1) :] + nn.functional.silu(conv(h, W[2 + 2 * li], W[3 + 2 * li], dilation=d, groups=n))
        y = conv(h, W[-4], W[-3], groups=n) + conv(x[..., rf - 1 :], W[-2], W[-1], groups=n)
        return y.view(len(x), n, n_out, -1)

    def gather(X, Y, uid, idx):  # idx [n, b] example indices of each live member
        xb = X[uid[:, None], idx]  # [n, b, cmax, L]
        n, b = idx.shape
        return xb.transpose(0, 1).reshape(b, n * cmax, -1), Y[uid[:, None], idx].transpose(0, 1)

    benchmark = torch.backends.cudnn.benchmark  # restored below: the setting is process-wide
    if dev.type == "cuda":  # the grouped dilated convolutions: let cuDNN time its algorithms once per shape
        torch.backends.cudnn.benchmark = True
    gens = [torch.Generator().manual_seed(int(c.seed)) for c in cfgs]
    hist = [TrainHistory(device=str(dev)) for _ in range(G)]
    best = [r.clone() for r in blocks]  # each member's best weights, [G, size] per layer (CPU)
    bad = [0] * G
    ids = member_ids(G)
    beta1, beta2, eps = 0.9, 0.999, 1e-8  # torch.optim.Adam's defaults (train_model)
    lr, wd, clip, bs = float(c0.lr), float(c0.weight_decay), c0.grad_clip, int(c0.batch_size)
    step = 0
    t0 = time.perf_counter()
    for epoch in range(int(c0.max_epochs)):
        n = len(live)
        batches = [list(torch.randperm(N, generator=gens[g]).split(bs)) for g in live]
        nb = len(batches[0]) if c0.max_batches_per_epoch is None else min(len(batches[0]), int(c0.max_batches_per_epoch))
        uid = uid_t
        tot = torch.zeros(n, device=dev)
        for i in range(nb):
            idx = torch.stack([b[i] for b in batches]).to(dev)
            xb, yb = gather(Xt, Yt, uid, idx)
            flat.requires_grad_(True)
            if dw:  # derivative matching: each member's own mean(e^2) + dw * mean((D_dk e)^2) along its chunks
                e = forward(flat, n, xb) - yb
                de = _diffs(e, dk)
                lossg = (e * e).mean((0, 2, 3)) + dw * (de * de).mean((0, 2, 3))
            else:
                lossg = ((forward(flat, n, xb) - yb) ** 2).mean((0, 2, 3))
            (g,) = torch.autograd.grad(lossg.sum(), flat)
            flat.requires_grad_(False)
            with torch.no_grad():
                if clip:
                    norm = torch.zeros(n, device=dev).index_add_(0, ids, g * g).sqrt()
                    g = g * torch.clamp(float(clip) / (norm + 1e-6), max=1.0)[ids]
                if wd:
                    g = g + wd * flat
                step += 1
                m1.lerp_(g, 1 - beta1)
                m2.mul_(beta2).addcmul_(g, g, value=1 - beta2)
                denom = (m2.sqrt() / math.sqrt(1 - beta2**step)).add_(eps)
                flat.addcdiv_(m1, denom, value=-lr / (1 - beta1**step))
                tot += lossg.detach() * idx.shape[1]
        n_seen = sum(len(batches[0][i]) for i in range(nb))
        tl = (tot / max(n_seen, 1)).double().cpu().tolist()
        if has_valid[0]:
            with torch.no_grad():
                sq = torch.zeros(n, device=dev, dtype=torch.float64)
                sqd = torch.zeros(n, device=dev, dtype=torch.float64)
                nv = len(Xv[0])
                allv = torch.arange(nv, device=dev)
                for a in range(0, nv, 1024):
                    j = allv[a : a + 1024].expand(n, -1)
                    xb, yb = gather(Xv, Yv, uid_v, j)
                    if dw:
                        e = forward(flat, n, xb) - yb
                        de = _diffs(e, dk)
                        sq += (e * e).sum((0, 2, 3)).double()
                        sqd += (de * de).sum((0, 2, 3)).double()
                    else:
                        sq += ((forward(flat, n, xb) - yb) ** 2).sum((0, 2, 3)).double()
                vl = sq / (nv * Yv.shape[2] * Yv.shape[3])
                if dw:
                    vl = vl + dw * sqd / (nv * Yv.shape[2] * (Yv.shape[3] - dk))
                vl = vl.cpu().tolist()
        else:
            vl = tl
        keep = []
        for pos, gm in enumerate(live):
            h = hist[gm]
            h.train_loss.append(tl[pos])
            h.valid_loss.append(vl[pos])
            if vl[pos] < h.best_loss - c0.min_delta:
                h.best_loss, h.best_epoch, bad[gm] = vl[pos], epoch, 0
                o = 0
                for li, sz in enumerate(sizes):
                    best[li][gm] = flat[o : o + n * sz].view(n, sz)[pos].detach().cpu()
                    o += n * sz
            else:
                bad[gm] += 1
            if bad[gm] >= c0.patience:
                h.stopped_early = True
            else:
                keep.append(pos)
        if not keep:
            break
        if len(keep) < n:  # stopped members leave the group (their rows, Adam moments and data ids)
            flat, m1, m2 = (rows_of(b, n, keep) for b in (flat, m1, m2))
            live = [live[p] for p in keep]
            kt = torch.tensor(keep, device=dev)
            uid_t = uid_t[kt]
            if has_valid[0]:
                uid_v = uid_v[kt]
            ids = member_ids(len(live))
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    torch.backends.cudnn.benchmark = benchmark
    secs = time.perf_counter() - t0
    for gm, net in enumerate(nets):
        net.to("cpu")
        with torch.no_grad():
            for li, (p, _) in enumerate(_layers(net)):
                w = best[li][gm].view(shapes[li])
                p.copy_(w[tuple(slice(0, s) for s in p.shape)])
        net.eval()
        hist[gm].seconds = secs
    return hist


def fit_tcn_group(members: list[TCNCompensator], zdata: list[tuple], seeds: list[int]) -> None:
    """Fit TCNCompensators whose fit_setup has run (zdata[g] = its (zx, zy, zv)) as one batched network
    (`train_tcn_group`): each built under its own seed as `TorchCompensator._fit` builds it, its own examples."""
    from learn.train import seeded

    trs, vas, cfgs = [], [], []
    diff = {(w, k if w else 10) for w, k in (m.diff_loss() for m in members)}  # weight 0: the lag plays no part
    if len(diff) != 1:
        raise ValueError(f"fit_tcn_group: the members must share diff_loss_weight and diff_loss_lag, got {sorted(diff)}")
    for m, (zx, zy, zv), s in zip(members, zdata, seeds):
        with seeded(s):
            m.net = m._build()
        m._prepare(zx)
        trs.append(m._examples(zx, zy, True))
        vas.append(m._examples(*zv, False) if zv is not None else None)
        cfgs.append(m.train_config(s))
    hists = train_tcn_group([m.net for m in members], trs, vas, cfgs, diff_loss=diff.pop())
    for m, h, tr, va, s in zip(members, hists, trs, vas, seeds):
        m.history = {**h.to_json(), "n_train_examples": len(tr[0]), "n_valid_examples": 0 if va is None else len(va[0]),
                     "n_parameters": sum(p.numel() for p in m.net.parameters()), "batched_members": len(members)}
        m.seed = int(s)

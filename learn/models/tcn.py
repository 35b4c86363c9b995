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
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from learn.models.base import Streamer, register
from learn.models.neural import TRAIN_DEFAULTS, TorchCompensator, _f32

__all__ = ["CausalTCN", "TCNCompensator", "play_gaps"]


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

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.feat is not None:
            if self.n_play:
                g = x[..., x.shape[-1] - self.n_play :]
                x = torch.cat([self.feat(x[..., : x.shape[-1] - self.n_play]), g], dim=-1)
            else:
                x = self.feat(x)
        x = x.transpose(1, 2)
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
                "chunk": 64, "batch_size": 16, "lr": 2e-3, "log_inputs": None, "play_widths": None}
    temporal = True

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
        self.reset()

    def reset(self) -> None:
        self.bufs: list[np.ndarray] | None = None
        self.t = 0
        self.play_p: np.ndarray | None = None

    def step(self, x: np.ndarray) -> np.ndarray:
        z = (np.asarray(x, np.float64).reshape(-1) - self.xm) / self.xs
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
        return y * self.ys + self.ym

"""Torch compensators: the common base (training through learn.train, state as safetensors), the
static MLP and the sliding-window recurrent nets of the cnt_pdms paper (stacked LSTM, one-layer GRU).

Window models read x_t = [x_{t-w+1} .. x_t] (cnt_pdms eq. 1) and regress y_t from the last hidden
state of the top layer (eq. 8). Streaming keeps a ring buffer of the last w normalised samples and runs
the net on it each sample: exactly the batch computation, and the paper's model as specified (each
window starts from a zero state).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from learn.models.base import Compensator, FnStreamer, Streamer, edge_windows, register
from learn.train import TrainConfig, seeded, train_model

__all__ = ["GRUCompensator", "LSTMCompensator", "MLPCompensator", "TorchCompensator", "WindowRNNCompensator"]

TRAIN_DEFAULTS: dict[str, Any] = {
    "lr": 1e-3, "batch_size": 64, "max_epochs": 200, "patience": 15, "grad_clip": 1.0,
    "max_batches_per_epoch": None,
}


def _f32(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))


class TorchCompensator(Compensator):
    """Subclasses give _build() (the nn.Module), _examples() (training tensors from normalised
    episodes) and _forward_seq() (normalised episode -> normalised estimates)."""

    net: nn.Module | None = None

    def _build(self) -> nn.Module:
        raise NotImplementedError

    def _examples(self, zx: list[np.ndarray], zy: list[np.ndarray], train: bool) -> tuple[torch.Tensor, torch.Tensor]:
        raise NotImplementedError

    def _forward_seq(self, z: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def train_config(self, seed: int) -> TrainConfig:
        h = self.hparams
        return TrainConfig(lr=h["lr"], batch_size=h["batch_size"], max_epochs=h["max_epochs"], patience=h["patience"],
                           grad_clip=h["grad_clip"], max_batches_per_epoch=h["max_batches_per_epoch"], seed=seed)

    def loss_fn(self):
        """The fit criterion handed to learn.train.train_model (None: the MSE)."""
        return None

    def _prepare(self, zx: list[np.ndarray]) -> None:
        """After the net is built, before training: set anything the net computes from the training inputs."""

    def _fit(self, zx, zy, zv, *, seed, progress):
        with seeded(seed):
            self.net = self._build()
        self._prepare(zx)
        tr = self._examples(zx, zy, True)
        va = self._examples(*zv, False) if zv is not None else None
        hist = train_model(self.net, tr, va, self.train_config(seed), progress=progress, description=self.kind,
                           loss_fn=self.loss_fn())
        return {**hist.to_json(), "n_train_examples": len(tr[0]), "n_valid_examples": 0 if va is None else len(va[0]),
                "n_parameters": sum(p.numel() for p in self.net.parameters())}

    @torch.inference_mode()
    def _predict_z(self, z):
        self.net.eval()
        return self._forward_seq(np.asarray(z, np.float64))

    def state_tensors(self):
        return {k: v.detach().cpu().numpy() for k, v in self.net.state_dict().items()}

    def load_state_tensors(self, tensors):
        self.net = self._build()
        self.net.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in tensors.items()})
        self.net.eval()


class MLP(nn.Module):
    def __init__(self, n_in: int, hidden: list[int], n_out: int):
        super().__init__()
        layers: list[nn.Module] = []
        prev = n_in
        for h in hidden:
            layers += [nn.Linear(prev, h), nn.ReLU()]
            prev = h
        layers.append(nn.Linear(prev, n_out))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class FramewiseCompensator(TorchCompensator):
    """A network that maps each sample on its own (no history): examples are the frames themselves."""

    def _examples(self, zx, zy, train):
        return _f32(np.concatenate(zx)), _f32(np.concatenate(zy))

    def _forward_seq(self, z):
        return self.net(_f32(z)).double().numpy()

    def _streamer(self) -> Streamer:
        net = self.net

        def f(z: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                return net(_f32(z[None]))[0].double().numpy()

        return FnStreamer(self, f)


@register("mlp")
class MLPCompensator(FramewiseCompensator):
    """cnt_pdms Table 3 "MLP": the current sample only; two ReLU layers of 64 (# estimate: the paper gives no size)."""

    DEFAULTS = {**TRAIN_DEFAULTS, "hidden": [64, 64]}

    def _build(self):
        return MLP(self.n_in, list(self.hparams["hidden"]), self.n_out)



class StackedRNN(nn.Module):
    """[B, w, n_in] -> [B, n_out]: RNN layers (dropout after each), dense head on the last step."""

    def __init__(self, cell: str, n_in: int, hidden: list[int], dropout: float, n_out: int):
        super().__init__()
        cls = {"lstm": nn.LSTM, "gru": nn.GRU}[cell]
        sizes = [n_in, *hidden]
        self.layers = nn.ModuleList(cls(a, b, batch_first=True) for a, b in zip(sizes[:-1], sizes[1:]))
        self.drop = nn.Dropout(dropout)
        self.head = nn.Linear(sizes[-1], n_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x
        for layer in self.layers:
            h, _ = layer(h)
            h = self.drop(h)
        return self.head(h[:, -1])


class WindowRNNCompensator(TorchCompensator):
    cell: ClassVar[str] = "lstm"
    temporal = True

    @property
    def context(self) -> int:
        return int(self.hparams["window"])

    def _build(self):
        h = self.hparams
        return StackedRNN(self.cell, self.n_in, list(h["hidden"]), h["dropout"], self.n_out)

    def _examples(self, zx, zy, train):
        w = self.context
        s = int(self.hparams["train_stride"]) if train else int(self.hparams.get("valid_stride", 1))
        X = np.concatenate([edge_windows(x, w)[::s] for x in zx])
        Y = np.concatenate([y[::s] for y in zy])
        return _f32(X), _f32(Y)

    def _forward_seq(self, z, bs: int = 2048):
        W = edge_windows(z, self.context)
        return np.concatenate([self.net(_f32(W[i : i + bs])).double().numpy() for i in range(0, len(W), bs)])

    def _streamer(self) -> Streamer:
        return WindowStreamer(self)


class WindowStreamer(Streamer):
    """Ring buffer of the last w normalised samples (first sample repeated at start); the net runs on it."""

    def __init__(self, comp: WindowRNNCompensator):
        self.comp = comp
        self.w = comp.context
        self.buf = torch.zeros(1, 2 * self.w, comp.n_in)  # doubled buffer: window is always contiguous
        self.reset()

    def reset(self) -> None:
        self.i = -1

    @torch.inference_mode()
    def step(self, x: np.ndarray) -> np.ndarray:
        c = self.comp
        z = torch.from_numpy(((np.asarray(x, np.float64).reshape(-1) - c.x_norm.mean) / c.x_norm.std).astype(np.float32))
        w = self.w
        if self.i < 0:
            self.buf[0, :, :] = z
            self.i = w - 1
        else:
            self.i += 1
            if self.i >= 2 * w:  # slide the last w-1 samples to the front
                self.buf[0, : w - 1] = self.buf[0, self.i - w + 1 : self.i].clone()
                self.i = w - 1
            self.buf[0, self.i] = z
        y = c.net(self.buf[:, self.i - w + 1 : self.i + 1])[0].double().numpy()
        return y * c.y_norm.std + c.y_norm.mean


RNN_DEFAULTS = {**TRAIN_DEFAULTS, "window": 50, "dropout": 0.2, "train_stride": 1, "valid_stride": 1}


@register("lstm")
class LSTMCompensator(WindowRNNCompensator):
    """cnt_pdms Table 2: w = 50, LSTM 128 -> LSTM 64 -> dense, dropout 0.2, Adam 1e-3, batch 64,
    <= 200 epochs, early stop 15, z-score on input and label."""

    cell = "lstm"
    DEFAULTS = {**RNN_DEFAULTS, "hidden": [128, 64]}


@register("gru")
class GRUCompensator(WindowRNNCompensator):
    """cnt_pdms Table 3 "GRU (1 layer)": w = 50, one GRU of 64 (# estimate: size not given), same training."""

    cell = "gru"
    DEFAULTS = {**RNN_DEFAULTS, "hidden": [64]}

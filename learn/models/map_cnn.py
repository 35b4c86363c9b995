"""Ours for array sensors: a small fully convolutional net over the element map (``map_cnn``).

Input: one frame of an ny x nx array with c channels per element, flattened element-major
([T, ny*nx*c], element m = iy*nx + ix, as the ntype recordings store [element, column]); output the same
layout with ``n_out / (ny*nx)`` targets per element (ntype: 36 x 3 resistances -> 36 x 3 forces).
Every element's estimate reads a square of (kernel - 1) x layers + 1 elements around it (7 x 7 by default)
through shared weights: the
learned version of the ntype paper's sliding window, with zero padding (= the training mean after the
per-feature z-score) beyond the border. Static (current frame only).
"""

from __future__ import annotations

import torch
from torch import nn

from learn.models.base import register
from learn.models.neural import TRAIN_DEFAULTS, FramewiseCompensator

__all__ = ["MapCNN", "MapCNNCompensator"]


class MapCNN(nn.Module):
    """[B, ny*nx*c_in] -> [B, ny*nx*c_out]: conv k x k (ReLU) x layers, then a 1 x 1 head."""

    def __init__(self, grid: tuple[int, int], c_in: int, c_out: int, channels: int, layers: int, kernel: int):
        super().__init__()
        self.ny, self.nx, self.c_in, self.c_out = grid[0], grid[1], c_in, c_out
        mods: list[nn.Module] = []
        prev = c_in
        for _ in range(layers):
            mods += [nn.Conv2d(prev, channels, kernel, padding=kernel // 2), nn.ReLU()]
            prev = channels
        mods.append(nn.Conv2d(prev, c_out, 1))
        self.net = nn.Sequential(*mods)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b = x.shape[0]
        z = x.reshape(b, self.ny, self.nx, self.c_in).permute(0, 3, 1, 2)
        return self.net(z).permute(0, 2, 3, 1).reshape(b, -1)


@register("map_cnn")
class MapCNNCompensator(FramewiseCompensator):
    """Hyper-parameters: grid [ny, nx] (6 x 6 for ntype), channels/layers/kernel of the conv stack."""

    DEFAULTS = {**TRAIN_DEFAULTS, "grid": [6, 6], "channels": 32, "layers": 3, "kernel": 3, "lr": 2e-3,
                "batch_size": 32, "weight_decay": 0.0}

    def _build(self):
        ny, nx = self.hparams["grid"]
        if self.n_in % (ny * nx) or self.n_out % (ny * nx):
            raise ValueError(f"map_cnn: {self.n_in} inputs / {self.n_out} outputs do not tile a {ny} x {nx} grid")
        h = self.hparams
        return MapCNN((ny, nx), self.n_in // (ny * nx), self.n_out // (ny * nx), h["channels"], h["layers"], h["kernel"])

    def train_config(self, seed):
        cfg = super().train_config(seed)
        cfg.weight_decay = float(self.hparams["weight_decay"])
        return cfg

"""Ours for the ntype array: a physics-informed per-element network (``ElementMLP``).

  strain      each column's resistance is inverted through the sensor's own law R = R0 (1 + e)^2 exp(beta e)
              (sensors/ntype/reference.py; R0 and beta from the recording's attributes) by Newton's method, so the
              network sees the column strains e_j, which are linear in the electrode force (e = N u / l,
              u = K^-1 F) instead of the exponential resistances. One global scale (the training std of e)
              keeps the shared physical scale across columns and elements (unlike a per-feature z-score).
  window      the strains of the element and its 8 neighbours (3 x 3, zeros = unloaded beyond the border)
              plus 4 position features (x, y, distance to the x and y borders), like the paper's sliding
              window but square: the cover spreads a load to all 8 neighbours.
  network     one MLP (2 x ``hidden`` GELU) shared by all 36 elements -> the element's (F_x, F_y, F_z);
              loss (p - y)^2 / (|y| + ``rel_floor``), close to the relative error eq. 14 for loaded components
              and to a plain squared error near zero; AdamW + cosine schedule, early stopping on held-out
              training episodes; trained on every loaded element row plus ``rest_keep`` of the unloaded ones.
  symmetry    every training frame is added transformed by the array's symmetry (``mirror``, chosen from the
              column reading, scenes/ntype_config.py): "transpose" (the "crossed" reading: x <-> y with
              R_x <-> R_y and F_x <-> F_y), "mirror_x" ("coplanar": x -> -x, R_x <-> R_y, F_x -> -F_x),
              "mirror_y" ("eq8": y -> -y, R_x <-> R_y, F_y -> -F_y), or "none".
  ensemble    ``n_seeds`` nets (different seeds and validation episodes), predictions averaged.
Static (the current frame only), like the paper's RBF.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

__all__ = ["SYMMETRY_OF_READING", "ElementMLP", "invert_strain", "mirror_x", "square_window", "symmetric_frames"]

GRID = (6, 6)


def invert_strain(R: np.ndarray, rest_ohm: np.ndarray, beta: float, iters: int = 8) -> np.ndarray:
    """R [..., 3] (ohm) -> e [..., 3] with R = R0 (1 + e)^2 exp(beta e) (Newton on the log, monotone for e > -1)."""
    L = np.log(np.maximum(np.asarray(R, np.float64), 1e-9) / np.asarray(rest_ohm, np.float64))
    e = L / (2.0 + beta)
    for _ in range(iters):
        e = np.maximum(e, -0.95)
        e = e - (2.0 * np.log1p(e) + beta * e - L) / (2.0 / (1.0 + e) + beta)
    return e


def square_window(E: np.ndarray, r: int = 1, grid: tuple[int, int] = GRID) -> np.ndarray:
    """E [N, ny*nx, c] -> [N*ny*nx, (2r+1)^2 c]: each element's (2r+1)^2 neighbourhood (row-major, dy outer),
    zeros beyond the border."""
    n, m, c = E.shape
    ny, nx = grid
    G = np.zeros((n, ny + 2 * r, nx + 2 * r, c))
    G[:, r : r + ny, r : r + nx] = E.reshape(n, ny, nx, c)
    cols = [G[:, r + dy : r + dy + ny, r + dx : r + dx + nx] for dy in range(-r, r + 1) for dx in range(-r, r + 1)]
    return np.concatenate(cols, -1).reshape(n * m, -1)


def position_features(n: int, grid: tuple[int, int] = GRID) -> np.ndarray:
    ny, nx = grid
    iy, ix = np.divmod(np.arange(ny * nx), nx)
    P = np.stack([ix / (nx - 1), iy / (ny - 1), np.minimum(ix, nx - 1 - ix) / ((nx - 1) / 2),
                  np.minimum(iy, ny - 1 - iy) / ((ny - 1) / 2)], -1)
    return np.tile(P, (n, 1))


def mirror_x(E: np.ndarray, F: np.ndarray, grid: tuple[int, int] = GRID) -> tuple[np.ndarray, np.ndarray]:
    """The x-mirrored frames: E [N, M, 3] (columns R_x, R_y, R_z) with R_x <-> R_y, F [N, M, 3] with F_x -> -F_x."""
    n = len(E)
    ny, nx = grid
    Em = E.reshape(n, ny, nx, 3)[:, :, ::-1][..., [1, 0, 2]].reshape(n, ny * nx, 3)
    Fm = F.reshape(n, ny, nx, 3)[:, :, ::-1].reshape(n, ny * nx, 3) * np.array([-1.0, 1.0, 1.0])
    return np.ascontiguousarray(Em), np.ascontiguousarray(Fm)


def symmetric_frames(E: np.ndarray, F: np.ndarray, kind: str, grid: tuple[int, int] = GRID) -> tuple[np.ndarray, np.ndarray]:
    """The frames under the array's symmetry `kind` ("mirror_x", "mirror_y", "transpose"); columns (R_x, R_y, R_z)."""
    if kind == "mirror_x":
        return mirror_x(E, F, grid)
    n = len(E)
    ny, nx = grid
    e, f = E.reshape(n, ny, nx, 3), F.reshape(n, ny, nx, 3)
    if kind == "mirror_y":
        Em = e[:, ::-1][..., [1, 0, 2]]
        Fm = f[:, ::-1] * np.array([1.0, -1.0, 1.0])
    elif kind == "transpose":
        if ny != nx:
            raise ValueError("transpose symmetry needs a square array")
        Em = np.swapaxes(e, 1, 2)[..., [1, 0, 2]]
        Fm = np.swapaxes(f, 1, 2)[..., [1, 0, 2]]
    else:
        raise ValueError(f"unknown symmetry '{kind}' (allowed: mirror_x, mirror_y, transpose)")
    return np.ascontiguousarray(Em.reshape(n, ny * nx, 3)), np.ascontiguousarray(Fm.reshape(n, ny * nx, 3))


SYMMETRY_OF_READING = {"crossed": "transpose", "coplanar": "mirror_x", "eq8": "mirror_y"}


class ElementMLP:
    """fit(R episodes [T, 36, 3] ohm, F episodes [T, 36, 3] N) -> self; predict(R [N, 36, 3]) -> F [N, 36, 3]."""

    DEFAULTS: dict[str, Any] = {"hidden": 64, "radius": 1, "n_seeds": 5, "max_epochs": 150, "patience": 20,
                                "batch_size": 256, "lr": 3e-3, "weight_decay": 0.0, "rel_floor": 0.3,
                                "rest_keep": 0.3, "valid_share": 0.1, "mirror": True}

    def __init__(self, rest_ohm: np.ndarray, beta: float, **hparams: Any):
        unknown = set(hparams) - set(self.DEFAULTS)
        if unknown:
            raise ValueError(f"ElementMLP: unknown hyper-parameters {sorted(unknown)}")
        self.h = {**self.DEFAULTS, **hparams}
        self.rest_ohm, self.beta = np.asarray(rest_ohm, np.float64).reshape(3), float(beta)
        self.nets: list[nn.Module] = []
        self.scale_: float | None = None
        self.history_: list[dict[str, Any]] = []

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {"rest_ohm": self.rest_ohm.tolist(), "beta": self.beta, **self.h}

    def _features(self, E: np.ndarray) -> np.ndarray:
        return np.concatenate([square_window(E / self.scale_, self.h["radius"]), position_features(len(E))], 1)

    def _net(self, n_in: int) -> nn.Module:
        k = int(self.h["hidden"])
        return nn.Sequential(nn.Linear(n_in, k), nn.GELU(), nn.Linear(k, k), nn.GELU(), nn.Linear(k, 3))

    def _rows(self, E: np.ndarray, F: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        kind = {True: "mirror_x", False: "none"}.get(self.h["mirror"], self.h["mirror"])
        if kind != "none":
            Em, Fm = symmetric_frames(E, F, kind)
            E, F = np.concatenate([E, Em]), np.concatenate([F, Fm])
        A, Y = self._features(E), F.reshape(-1, 3)
        loaded = np.abs(Y).max(1) > 0.02
        keep = loaded | (rng.random(len(Y)) < self.h["rest_keep"])
        return A[keep], Y[keep]

    def fit(self, R: list[np.ndarray], F: list[np.ndarray], seed: int = 0) -> ElementMLP:
        h = self.h
        E = [invert_strain(r, self.rest_ohm, self.beta) for r in R]
        self.scale_ = float(np.concatenate(E).std()) or 1.0
        self.nets, self.history_ = [], []
        rel = float(h["rel_floor"])

        def loss(p: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
            return (((p - y) ** 2) / (y.abs() + rel)).mean()

        for s in range(int(h["n_seeds"])):
            rng = np.random.default_rng([seed, s])
            order = rng.permutation(len(E))
            nv = max(1, int(round(h["valid_share"] * len(E)))) if len(E) > 1 else 0
            va, tr = order[:nv], order[nv:]
            A, Y = self._rows(np.concatenate([E[i] for i in tr]), np.concatenate([F[i] for i in tr]), rng)
            a, b = torch.from_numpy(A.astype(np.float32)), torch.from_numpy(Y.astype(np.float32))
            if nv:
                Ev, Fv = np.concatenate([E[i] for i in va]), np.concatenate([F[i] for i in va])
                av = torch.from_numpy(self._features(Ev).astype(np.float32))
                bv = torch.from_numpy(Fv.reshape(-1, 3).astype(np.float32))
            torch.manual_seed(int(rng.integers(2**31)))
            net = self._net(A.shape[1])
            opt = torch.optim.AdamW(net.parameters(), h["lr"], weight_decay=h["weight_decay"])
            sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, int(h["max_epochs"]))
            best, state, bad, ep = float("inf"), None, 0, 0
            for ep in range(int(h["max_epochs"])):
                net.train()
                perm = torch.randperm(len(a))
                for i in range(0, len(a), int(h["batch_size"])):
                    j = perm[i : i + int(h["batch_size"])]
                    opt.zero_grad()
                    loss(net(a[j]), b[j]).backward()
                    opt.step()
                sched.step()
                net.eval()
                with torch.no_grad():
                    v = loss(net(av), bv).item() if nv else loss(net(a), b).item()
                if v < best:
                    best, state, bad = v, {k: t.clone() for k, t in net.state_dict().items()}, 0
                else:
                    bad += 1
                    if bad > int(h["patience"]):
                        break
            net.load_state_dict(state)
            net.eval()
            self.nets.append(net)
            self.history_.append({"epochs": ep + 1, "best_valid_loss": best, "n_rows": len(a)})
        return self

    @torch.inference_mode()
    def predict(self, R: np.ndarray) -> np.ndarray:
        if not self.nets:
            raise RuntimeError("ElementMLP: not fitted")
        R = np.asarray(R, np.float64)
        A = torch.from_numpy(self._features(invert_strain(R, self.rest_ohm, self.beta)).astype(np.float32))
        p = np.mean([net(A).double().numpy() for net in self.nets], 0)
        return p.reshape(R.shape)

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

import math
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


SYMMETRY_OF_READING = {"crossed": "transpose", "coplanar": "mirror_x", "eq8": "mirror_y", "decoupled": "transpose"}


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
        self.params_: list[torch.Tensor] | None = None  # the batched members' weights [S, ...] (fit)

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

    def _member_data(self, E: list[np.ndarray], F: list[np.ndarray], seed: int, s: int):
        """Member s's draws, in fit_sequential's order: its generator, training rows, validation rows, torch seed."""
        h = self.h
        rng = np.random.default_rng([seed, s])
        order = rng.permutation(len(E))
        nv = max(1, int(round(h["valid_share"] * len(E)))) if len(E) > 1 else 0
        va, tr = order[:nv], order[nv:]
        A, Y = self._rows(np.concatenate([E[i] for i in tr]), np.concatenate([F[i] for i in tr]), rng)
        if nv:
            Ev, Fv = np.concatenate([E[i] for i in va]), np.concatenate([F[i] for i in va])
            Av, Yv = self._features(Ev), Fv.reshape(-1, 3)
        else:
            Av, Yv = A, Y
        return A, Y, Av, Yv, int(rng.integers(2**31))

    def fit(self, R: list[np.ndarray], F: list[np.ndarray], seed: int = 0) -> ElementMLP:
        """Train the ``n_seeds`` members as one batched network (weights [S, ...], torch.baddbmm) on the torch
        device of the enclosing `learn.train.training_device` block (the CPU outside one). Every member keeps
        its own draws (rows, validation episodes, initial weights, batch order: fit_sequential's), its own AdamW
        state and step count, and its own early stopping (a stopped member is frozen at its best epoch): the
        same training as one net after another, up to float summation order (tests/test_learn_ntype.py)."""
        from learn.train import current_device

        h = self.h
        dev = torch.device(current_device())
        E = [invert_strain(r, self.rest_ohm, self.beta) for r in R]
        self.scale_ = float(np.concatenate(E).std()) or 1.0
        self.nets, self.history_ = [], []
        S, bs, k = int(h["n_seeds"]), int(h["batch_size"]), int(h["hidden"])
        rel = float(h["rel_floor"])
        members = [self._member_data(E, F, seed, s) for s in range(S)]
        n_in = members[0][0].shape[1]
        sizes = [(n_in, k), (k, k), (k, 3)]
        gens = []
        Ws: list[list[torch.Tensor]] = [[] for _ in range(2 * len(sizes))]
        for m in members:  # nn.Linear's init (kaiming_uniform a=sqrt(5), bias U(+-1/sqrt(fan_in))) from its seed
            g = torch.Generator().manual_seed(m[4])
            gens.append(g)
            for li, (fi, fo) in enumerate(sizes):
                wb = math.sqrt(3.0) * (math.sqrt(2.0 / 6.0) / math.sqrt(fi))  # kaiming_uniform_'s bound, as torch computes it
                Ws[2 * li].append(torch.empty(fo, fi).uniform_(-wb, wb, generator=g).T)
                b = 1.0 / math.sqrt(fi)
                Ws[2 * li + 1].append(torch.empty(fo).uniform_(-b, b, generator=g)[None, :])
        # every member's weights in one flat buffer [S, T] (views per layer): one AdamW update of a few
        # elementwise kernels a step instead of one set per tensor (same arithmetic, element by element)
        stacked = [torch.stack(w) for w in Ws]
        shapes = [t.shape[1:] for t in stacked]
        flat = torch.cat([t.reshape(S, -1) for t in stacked], 1).to(dev).requires_grad_(True)

        def unpack(buf: torch.Tensor) -> list[torch.Tensor]:
            out, o = [], 0
            for shp in shapes:
                sz = math.prod(shp)
                out.append(buf[:, o : o + sz].view(buf.shape[0], *shp))
                o += sz
            return out

        n = [len(m[0]) for m in members]

        def pad(rows: list[np.ndarray], width: int) -> torch.Tensor:
            out = np.zeros((S, max(len(r) for r in rows), width), np.float32)
            for s, r in enumerate(rows):
                out[s, : len(r)] = r
            return torch.from_numpy(out).to(dev)

        a, b = pad([m[0] for m in members], n_in), pad([m[1] for m in members], 3)
        av, bv = pad([m[2] for m in members], n_in), pad([m[3] for m in members], 3)
        nv = torch.tensor([len(m[2]) for m in members], device=dev)
        vmask = (torch.arange(av.shape[1], device=dev)[None, :] < nv[:, None]).float()[..., None]

        forward = self._forward

        def member_loss(p: torch.Tensor, y: torch.Tensor, mask: torch.Tensor, count: torch.Tensor) -> torch.Tensor:
            return ((((p - y) ** 2) / (y.abs() + rel)) * mask).sum((1, 2)) / (3.0 * count.clamp(min=1))

        # AdamW as torch.optim.AdamW(lr, weight_decay; betas 0.9, 0.999, eps 1e-8), per member: a member takes a
        # step only when its batch holds rows and it has not stopped early
        beta1, beta2, eps, wd = 0.9, 0.999, 1e-8, float(h["weight_decay"])
        m1 = torch.zeros_like(flat)
        m2 = torch.zeros_like(flat)
        steps = torch.zeros(S, dtype=torch.float64)
        epochs = int(h["max_epochs"])
        best = [float("inf")] * S
        state: list[torch.Tensor | None] = [None] * S
        bad, done, last_ep = [0] * S, [False] * S, [0] * S
        ar = torch.arange(S, device=dev)[:, None]
        for ep in range(epochs):
            lr = h["lr"] * (1 + math.cos(math.pi * ep / epochs)) / 2  # CosineAnnealingLR(T_max = max_epochs)
            perms = [torch.randperm(n[s], generator=gens[s]) for s in range(S)]
            live = [not d for d in done]
            nsteps = max(-(-n[s] // bs) for s in range(S) if live[s])
            P = torch.zeros((S, nsteps * bs), dtype=torch.long)
            M = torch.zeros((S, nsteps * bs), dtype=torch.bool)
            for s in range(S):
                if live[s]:
                    P[s, : n[s]] = perms[s]
                    M[s, : n[s]] = True
            cnt = M.view(S, nsteps, bs).sum(2).T  # [nsteps, S] rows of each member's batch (CPU: no device sync)
            act = cnt > 0
            st = (steps[None, :] + act.double().cumsum(0)).clamp(min=1)  # each member's AdamW step count
            steps += act.double().sum(0)
            bc1 = (1 - beta1 ** st).float().to(dev)
            bc2s = (1 - beta2 ** st).sqrt().float().to(dev)
            P, M, cnt_d, act_d = P.to(dev), M.to(dev), cnt.float().to(dev), act.to(dev)
            # the members still training (the others stopped early: no rows, no step, not computed)
            sub = None if all(live) else torch.tensor([s for s in range(S) if live[s]], device=dev)
            if sub is not None:
                P, M, cnt_d = P[sub], M[sub], cnt_d[:, sub]
                a_l, b_l, ar_l = a[sub], b[sub], ar[: len(sub)]
            for i in range(nsteps):
                if not bool(act[i].any()):
                    continue
                j, msk = P[:, i * bs : (i + 1) * bs], M[:, i * bs : (i + 1) * bs]
                if sub is None:
                    x, y, W = a[ar, j], b[ar, j], unpack(flat)
                else:
                    x, y, W = a_l[ar_l, j], b_l[ar_l, j], [t[sub] for t in unpack(flat)]
                loss = member_loss(forward(x, W), y, msk.float()[..., None], cnt_d[i]).sum()
                (g,) = torch.autograd.grad(loss, flat)
                with torch.no_grad():
                    am = act_d[i].view(S, 1)
                    nm1 = torch.where(am, m1.lerp(g, 1 - beta1), m1)
                    nm2 = torch.where(am, m2 * beta2 + (1 - beta2) * g * g, m2)
                    m1.copy_(nm1)
                    m2.copy_(nm2)
                    upd = flat * (1 - lr * wd) - (lr / bc1[i].view(S, 1)) * nm1 / (nm2.sqrt() / bc2s[i].view(S, 1) + eps)
                    flat.copy_(torch.where(am, upd, flat))
            with torch.no_grad():
                vl = (member_loss(forward(av, unpack(flat)), bv, vmask, nv.to(av.dtype))).double().cpu().numpy()
            for s in range(S):
                if done[s]:
                    continue
                last_ep[s] = ep
                v = float(vl[s])
                if v < best[s]:
                    best[s], bad[s] = v, 0
                    state[s] = flat[s].detach().clone()
                else:
                    bad[s] += 1
                    if bad[s] > int(h["patience"]):
                        done[s] = True
            if all(done):
                break
        self.params_ = [t.contiguous() for t in unpack(torch.stack(state).cpu())]
        self.history_ = [{"epochs": last_ep[s] + 1, "best_valid_loss": best[s], "n_rows": n[s], "device": str(dev)}
                         for s in range(S)]
        return self

    def fit_sequential(self, R: list[np.ndarray], F: list[np.ndarray], seed: int = 0) -> ElementMLP:
        """The reference: the members trained one after another as separate nn.Sequential nets (session 9's fit).
        `fit` trains them as one batched network with the same draws; the two agree up to float summation order."""
        h = self.h
        E = [invert_strain(r, self.rest_ohm, self.beta) for r in R]
        self.scale_ = float(np.concatenate(E).std()) or 1.0
        self.nets, self.history_, self.params_ = [], [], None
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

    @staticmethod
    def _forward(x: torch.Tensor, P: list[torch.Tensor]) -> torch.Tensor:
        """The members' 2 x hidden GELU MLPs at once: x [S, N, n_in], P = (W1, b1, W2, b2, W3, b3) stacked [S, ...]."""
        z = torch.nn.functional.gelu(torch.baddbmm(P[1], x, P[0]))
        z = torch.nn.functional.gelu(torch.baddbmm(P[3], z, P[2]))
        return torch.baddbmm(P[5], z, P[4])

    @torch.inference_mode()
    def predict(self, R: np.ndarray) -> np.ndarray:
        if not self.nets and self.params_ is None:
            raise RuntimeError("ElementMLP: not fitted")
        R = np.asarray(R, np.float64)
        A = torch.from_numpy(self._features(invert_strain(R, self.rest_ohm, self.beta)).astype(np.float32))
        if self.params_ is not None:  # the batched members (fit): [S, N, 3], averaged in float64
            S = self.params_[0].shape[0]
            p = self._forward(A[None].expand(S, -1, -1), self.params_).double().mean(0).numpy()
        else:
            p = np.mean([net(A).double().numpy() for net in self.nets], 0)
        return p.reshape(R.shape)

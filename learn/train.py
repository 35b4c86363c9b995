"""A seeded mini-batch training loop: Adam on MSE, early stopping on the validation loss, rich progress.

Deterministic for a given seed on CPU: the weights are initialised under ``torch.manual_seed(seed)``
(the caller builds the net inside `seeded`), the batch order comes from a private generator, and the
best epoch's weights are restored at the end. Inputs and targets arrive already z-scored; the
statistics live with the compensator (learn.models.base), not here.

Device: training runs where `TrainConfig.device` says, else where the innermost `training_device(...)` block
says (the CLI's `--train-device`), else on the CPU. On a CUDA device the net and the examples are moved there
for the epochs and the net comes back to the CPU with its best weights, so prediction, streaming and
checkpoints are unchanged; the batch order is drawn on the CPU either way. CUDA kernels sum in another order
than the CPU's, so a CUDA run is reproducible on its own device (same seed, same GPU) but not bit-equal to the
CPU run; the history records the device (`TrainHistory.device`).
"""

from __future__ import annotations

import contextlib
import contextvars
import copy
import math
import re
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

import torch
from torch import nn

__all__ = ["TrainConfig", "TrainHistory", "current_device", "resolve_device", "seeded", "single_thread", "stopping_epoch", "train_model",
           "training_device"]

TRAIN_DEVICES = ("cpu", "cuda", "auto")  # what --train-device accepts (also "cuda:N")
_DEVICE: contextvars.ContextVar[str] = contextvars.ContextVar("piezotwin_train_device", default="cpu")


def resolve_device(name: str) -> str:
    """"cpu", "cuda", "cuda:N" or "auto" (CUDA when torch sees a device, else the CPU) -> a concrete torch device
    string; ValueError naming the allowed values, or saying that torch sees no CUDA device."""
    name = str(name).strip().lower()
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return "cpu"
    if name == "cuda" or re.fullmatch(r"cuda:\d+", name):
        if not torch.cuda.is_available():
            raise ValueError(f"train device '{name}': this torch ({torch.__version__}) sees no CUDA device "
                             "(use cpu or auto)")
        idx = int(name.split(":")[1]) if ":" in name else 0
        if idx >= torch.cuda.device_count():
            raise ValueError(f"train device '{name}': torch sees {torch.cuda.device_count()} CUDA device(s)")
        return name
    raise ValueError(f"train device must be one of {', '.join(TRAIN_DEVICES)} or cuda:N (got '{name}')")


def current_device() -> str:
    """The device the innermost `training_device` block chose ("cpu" outside any)."""
    return _DEVICE.get()


@contextlib.contextmanager
def training_device(name: str) -> Iterator[str]:
    """Train every `train_model` call inside the block on ``name`` (see `resolve_device`); yields the concrete
    device."""
    token = _DEVICE.set(resolve_device(name))
    try:
        yield _DEVICE.get()
    finally:
        _DEVICE.reset(token)


@dataclass
class TrainConfig:
    lr: float = 1e-3
    batch_size: int = 64
    max_epochs: int = 200
    patience: int = 15  # epochs without a validation improvement before stopping
    min_delta: float = 0.0  # an improvement must lower the loss by more than this
    weight_decay: float = 0.0
    grad_clip: float | None = 1.0
    max_batches_per_epoch: int | None = None  # a random subset of batches each epoch (quick runs)
    seed: int = 0
    device: str | None = None  # None: the innermost training_device block's (the CPU outside any)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class TrainHistory:
    train_loss: list[float] = field(default_factory=list)
    valid_loss: list[float] = field(default_factory=list)
    best_epoch: int = -1
    best_loss: float = math.inf
    stopped_early: bool = False
    seconds: float = 0.0
    device: str = "cpu"  # where the epochs ran

    @property
    def epochs(self) -> int:
        return len(self.train_loss)

    def to_json(self) -> dict[str, Any]:
        return {
            "epochs": self.epochs, "best_epoch": self.best_epoch, "best_loss": self.best_loss,
            "stopped_early": self.stopped_early, "seconds": self.seconds, "device": self.device,
            "train_loss": self.train_loss, "valid_loss": self.valid_loss,
        }


def single_thread(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Run ``fn`` with torch on one intra-op thread (restored afterwards). The nets here are small: two threads
    contending for two busy cores were several times slower than one. And a float sum split over threads is summed
    in another order, so a training run's numbers would depend on the machine's core count (a pre-trained net,
    then everything fine-tuned from it); on one thread they are a function of the data and the seeds alone."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        old = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return fn(*args, **kwargs)
        finally:
            torch.set_num_threads(old)

    return wrapper


@contextlib.contextmanager
def seeded(seed: int) -> Iterator[None]:
    """Fork torch's global RNG, seed it, and restore it afterwards (so building a net is reproducible
    without disturbing the caller's randomness)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        yield


def _batches(n: int, bs: int, gen: torch.Generator, limit: int | None) -> list[torch.Tensor]:
    perm = torch.randperm(n, generator=gen)
    out = list(perm.split(bs))
    if limit is not None and len(out) > limit:
        out = out[:limit]
    return out


@torch.no_grad()
def evaluate(net: nn.Module, x: torch.Tensor, y: torch.Tensor, bs: int = 1024,
             loss_fn: Callable | None = None) -> float:
    loss_fn = loss_fn or nn.functional.mse_loss
    net.eval()
    dev = next((p.device for p in net.parameters()), torch.device("cpu"))
    tot, n = 0.0, 0
    for i in range(0, len(x), bs):
        xb, yb = x[i : i + bs].to(dev), y[i : i + bs].to(dev)
        tot += float(loss_fn(net(xb), yb, reduction="sum"))
        n += yb.numel()
    return tot / max(n, 1)


def stopping_epoch(curve: list[float], patience: int, keep_initial: bool = True) -> int:
    """The epoch `train_model` restores on a validation curve, replayed: with ``keep_initial`` curve[0] is epoch -1
    (the arriving weights) and curve[i + 1] epoch i, else curve[i] is epoch i; an epoch is best when it lowers the
    best loss so far (min_delta 0), training stops after ``patience`` epochs without one. Training itself does not
    depend on the patience, so one run to the epoch cap gives every patience's result (bench/bench_s2r_patience.py)."""
    best, best_e, bad = (curve[0], -1, 0) if keep_initial else (math.inf, -1, 0)
    for e, v in enumerate(curve[1:] if keep_initial else curve):
        if v < best:
            best, best_e, bad = v, e, 0
        else:
            bad += 1
        if bad >= patience:
            break
    return best_e


def _probe(fn: Callable[[int, nn.Module], None], epoch: int, net: nn.Module) -> None:
    net.eval()
    with torch.no_grad():
        fn(epoch, net)


def train_model(
    net: nn.Module,
    train: tuple[torch.Tensor, torch.Tensor],
    valid: tuple[torch.Tensor, torch.Tensor] | None,
    cfg: TrainConfig,
    *,
    progress: bool = True,
    description: str = "train",
    keep_initial: bool = False,
    penalty: Callable[[], torch.Tensor] | None = None,
    on_epoch: Callable[[int, nn.Module], None] | None = None,
    loss_fn: Callable[..., torch.Tensor] | None = None,
) -> TrainHistory:
    """Train ``net`` so that ``net(x) ~ y`` in MSE; returns the history; leaves the best weights loaded.

    ``train``/``valid`` are (inputs, targets) tensors whose first axis indexes examples; any
    shapes the net accepts. Without ``valid`` the training loss drives early stopping.
    ``keep_initial``: the weights the net arrives with are a candidate too (epoch -1, their validation loss
    before any step): fine-tuning that never improves on the pre-trained net returns it unchanged instead of
    the first epoch's weights.
    ``penalty``: a term added to each batch's training loss (e.g. L2-SP's pull toward the pre-trained weights,
    learn.finetune); the validation loss that stops early stays the plain MSE.
    ``loss_fn``: the fit criterion in place of the MSE, ``loss_fn(estimate, target)`` the batch's mean and
    ``loss_fn(estimate, target, reduction="sum")`` a sum whose mean per target element is that mean (`evaluate`);
    it is the training loss and the validation loss that stops early (e.g. the TCN's derivative matching,
    learn.models.tcn.diff_matched_mse). None: the MSE, as before.
    """
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    dev = torch.device(resolve_device(cfg.device) if cfg.device is not None else current_device())
    xt, yt = (t.to(dev) for t in train)
    if valid is not None:
        valid = (valid[0].to(dev), valid[1].to(dev))
    net.to(dev)  # before the optimiser sees the parameters
    gen = torch.Generator().manual_seed(int(cfg.seed))
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    hist = TrainHistory(device=str(dev))
    best_state = copy.deepcopy(net.state_dict())
    bad = 0
    if keep_initial and valid is not None:
        hist.best_loss, hist.best_epoch = evaluate(net, *valid, loss_fn=loss_fn), -1
    if on_epoch is not None:
        _probe(on_epoch, -1, net)
    t0 = time.perf_counter()
    cols = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("epochs"),
            TimeElapsedColumn(), TextColumn("{task.fields[info]}"))
    with Progress(*cols, console=Console(stderr=True), transient=True, disable=not progress) as bar:
        task = bar.add_task(description, total=cfg.max_epochs, info="")
        for epoch in range(cfg.max_epochs):
            net.train()
            tot, n = 0.0, 0
            for idx in _batches(len(xt), cfg.batch_size, gen, cfg.max_batches_per_epoch):
                idx = idx.to(dev)
                xb, yb = xt[idx], yt[idx]
                opt.zero_grad(set_to_none=True)
                loss = nn.functional.mse_loss(net(xb), yb) if loss_fn is None else loss_fn(net(xb), yb)
                (loss + penalty() if penalty is not None else loss).backward()
                if cfg.grad_clip:
                    nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
                opt.step()
                tot += float(loss.detach()) * len(idx)
                n += len(idx)
            hist.train_loss.append(tot / max(n, 1))
            vl = evaluate(net, *valid, loss_fn=loss_fn) if valid is not None else hist.train_loss[-1]
            hist.valid_loss.append(vl)
            if on_epoch is not None:
                _probe(on_epoch, epoch, net)
            if vl < hist.best_loss - cfg.min_delta:
                hist.best_loss, hist.best_epoch, bad = vl, epoch, 0
                best_state = copy.deepcopy(net.state_dict())
            else:
                bad += 1
            bar.update(task, advance=1, info=f"loss {hist.train_loss[-1]:.4g} valid {vl:.4g} best {hist.best_loss:.4g}@{hist.best_epoch}")
            if bad >= cfg.patience:
                hist.stopped_early = True
                break
    net.load_state_dict(best_state)
    net.to("cpu")  # prediction, streaming and checkpoints work on the CPU
    net.eval()
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    hist.seconds = time.perf_counter() - t0
    return hist

"""Time of ours' training at the velostat full budget: the 9 TCN members (3 input sets x 3 seeds) as one batched
network (learn.models.tcn.train_tcn_group) against one member alone (learn.train.train_model), on full-size
synthetic examples (N training chunks of 128 outputs + 254 samples of history, the full run's count: ~294 training
episodes of 150-170 s at 10 Hz, chunk stride 64), a few steps each, scaled to one epoch of N / 16 batches.

    PYTHONPATH=. python bench/bench_tcn_group.py [--device cpu|cuda] [--steps 20] [--n 7300]
Prints seconds per step and per epoch; the numbers go into the report by hand of whoever runs it (no result file).
"""

from __future__ import annotations

import argparse
import time

import torch

from learn.models.tcn import CausalTCN, train_tcn_group
from learn.train import TrainConfig, seeded, train_model


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--n", type=int, default=7300)
    ap.add_argument("--members", type=int, default=9)
    a = ap.parse_args()
    torch.set_num_threads(1)
    dil, chunk = [1, 2, 4, 8, 16, 32, 64], 128
    rf = 1 + 2 * sum(dil)
    sets = [4, 8, 9][: max(1, min(3, a.members))]
    nets, trains, valids, cfgs = [], [], [], []
    g = torch.Generator().manual_seed(0)
    data = {c: (torch.randn(a.n, chunk + rf - 1, c, generator=g), torch.randn(a.n, chunk, 1, generator=g)) for c in sets}
    vdata = {c: (torch.randn(900, chunk + rf - 1, c, generator=g), torch.randn(900, chunk, 1, generator=g)) for c in sets}
    for k in range(a.members):
        c = sets[k % len(sets)]
        with seeded(k):
            nets.append(CausalTCN(c, 1, 32, 3, dil))
        trains.append(data[c])
        valids.append(vdata[c])
        # max_batches_per_epoch = steps, patience high: one epoch of `steps` batches, then the validation
        cfgs.append(TrainConfig(lr=2e-3, batch_size=16, max_epochs=1, patience=100, max_batches_per_epoch=a.steps,
                                seed=k, device=a.device))
    # warm-up on the same shapes (oneDNN / cuDNN pick and compile their kernels on the first calls of each shape)
    warm = [TrainConfig(**{**c.to_json(), "max_batches_per_epoch": 3}) for c in cfgs]
    train_tcn_group(nets, trains, [None] * len(nets), warm)
    train_model(nets[0], trains[0], None, warm[0], progress=False)
    t0 = time.perf_counter()
    h = train_tcn_group(nets, trains, [None] * len(nets), cfgs)
    grp = time.perf_counter() - t0
    one_step = [TrainConfig(**{**c.to_json(), "max_batches_per_epoch": 1}) for c in cfgs]
    t0 = time.perf_counter()
    train_tcn_group(nets, trains, valids, one_step)
    val = time.perf_counter() - t0 - grp / a.steps
    t0 = time.perf_counter()
    train_model(nets[0], trains[0], None, cfgs[0], progress=False)
    one = time.perf_counter() - t0
    nb = -(-a.n // 16)
    print(f"device {a.device}, N {a.n} ({nb} batches of 16 an epoch), {a.steps} steps; validation on 900 examples")
    print(f"group of {a.members}: {grp:.2f} s -> {grp / a.steps * 1e3:.1f} ms a step, validation {val:.2f} s; "
          f"~{grp / a.steps * nb + val:.0f} s an epoch; history seconds {h[0].seconds:.2f}")
    print(f"one member alone (train_model): {one:.2f} s -> {one / a.steps * 1e3:.1f} ms a step, ~{one / a.steps * nb:.0f} s "
          f"an epoch; {a.members} one after another ~{a.members * one / a.steps * nb:.0f} s an epoch")


if __name__ == "__main__":
    main()

"""Where the nets train (learn.train's device): the CPU default is untouched by the device plumbing, the
CLI's --train-device is validated (exit 2, the allowed values named), and on CUDA (marked gpu) the nets of
the papers' compensators train there, learn as well as on the CPU, and come back to the CPU."""

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from learn.models import make_model
from learn.train import (
    TrainConfig,
    current_device,
    resolve_device,
    train_model,
    training_device,
)
from piezotwin.cli import app

torch.set_num_threads(1)


def _problem(n=12, seed=0):
    """A lagged, saturating 'sensor' (first-order lag 60 ms, then 1 - exp): force from the reading."""
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for k in range(n):
        t = np.arange(200) / 100.0
        F = rng.uniform(1, 5) * 0.5 * (1 - np.cos(2 * np.pi * [0.5, 1.0, 2.0][k % 3] * t))
        lag = np.zeros_like(F)
        for i in range(1, len(F)):
            lag[i] = lag[i - 1] + (F[i] - lag[i - 1]) * (1 - np.exp(-0.01 / 0.06))
        xs.append((1 - np.exp(-lag / 3))[:, None])
        ys.append(F[:, None])
    return xs, ys


def test_cpu_default_and_explicit_cpu_train_the_same_weights():
    x = torch.linspace(-1, 1, 64)[:, None]
    nets = []
    for cfg_dev, ctx in ((None, None), ("cpu", None), (None, "cpu")):
        torch.manual_seed(3)
        net = torch.nn.Sequential(torch.nn.Linear(1, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1))
        cfg = TrainConfig(lr=1e-2, max_epochs=5, batch_size=16, seed=1, device=cfg_dev)
        if ctx is None:
            h = train_model(net, (x, x**2), (x, x**2), cfg, progress=False)
        else:
            with training_device(ctx):
                h = train_model(net, (x, x**2), (x, x**2), cfg, progress=False)
        assert h.device == "cpu" and h.to_json()["device"] == "cpu"
        nets.append([p.detach().clone() for p in net.parameters()])
    for other in nets[1:]:
        for a, b in zip(nets[0], other):
            assert torch.equal(a, b)


def test_training_device_block_nests_and_restores():
    assert current_device() == "cpu"
    with training_device("auto") as d:
        assert d == ("cuda" if torch.cuda.is_available() else "cpu") and current_device() == d
        with training_device("cpu"):
            assert current_device() == "cpu"
        assert current_device() == d
    assert current_device() == "cpu"


@pytest.mark.parametrize("bad", ["gpu", "CUDA:x", "", "tpu"])
def test_resolve_device_names_the_allowed_values(bad):
    with pytest.raises(ValueError, match="cpu, cuda, auto or cuda:N"):
        resolve_device(bad)


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on a machine without CUDA")
def test_cli_train_device_cuda_without_cuda_exits_2(tmp_path):
    r = CliRunner().invoke(app, ["experiment", "cnt_pdms", "--quick", "-o", str(tmp_path / "x"), "--train-device", "cuda"])
    assert r.exit_code == 2 and "sees no CUDA device" in r.output
    r = CliRunner().invoke(app, ["experiment", "cnt_pdms", "--quick", "-o", str(tmp_path / "x"), "--train-device", "gpu"])
    assert r.exit_code == 2 and "cpu, cuda, auto or cuda:N" in r.output
    assert not (tmp_path / "x").exists()  # nothing made before the check


@pytest.mark.parametrize("bad", ["0", "-1", "two", "1.5", ""])
def test_cli_workers_names_the_allowed_values(tmp_path, bad):
    r = CliRunner().invoke(app, ["experiment", "ntype", "--quick", "-o", str(tmp_path / "x"), "--workers", bad])
    assert r.exit_code == 2 and "--workers must be auto or a whole number >= 1" in r.output
    assert not (tmp_path / "x").exists()  # nothing made before the check


@pytest.mark.gpu
@pytest.mark.parametrize("kind", ["lstm", "tcn", "mlp"])
def test_cuda_training_learns_as_on_cpu_and_returns_to_cpu(kind):
    if not torch.cuda.is_available():
        pytest.skip("needs CUDA")
    hp = {"mlp": {"max_epochs": 40, "patience": 10, "hidden": [16]},
          "lstm": {"max_epochs": 40, "patience": 10, "hidden": [16, 8], "window": 20, "train_stride": 3, "lr": 1e-2,
                   "batch_size": 32},
          "tcn": {"max_epochs": 40, "patience": 10, "channels": 8, "dilations": [1, 2, 4, 8]}}[kind]
    xs, ys = _problem()
    tx, ty = _problem(4, seed=9)
    rmse = {}
    for dev in ("cpu", "cuda"):
        with training_device(dev):
            comp = make_model(kind, **hp).fit(xs[:9], ys[:9], valid=(xs[9:], ys[9:]), seed=0)
        assert comp.history["device"].startswith(dev)
        assert all(p.device.type == "cpu" for p in comp.net.parameters())
        rmse[dev] = float(np.sqrt(np.mean(np.concatenate([(comp.predict(x) - y) ** 2 for x, y in zip(tx, ty)]))))
    spread = float(np.std(np.concatenate(ty)))
    assert rmse["cuda"] < 0.5 * spread and rmse["cuda"] < 1.5 * rmse["cpu"] + 0.02 * spread, rmse

"""WindowDataset: exact windows against numpy slicing, selection, DataLoader workers."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from sensors.data import manifest as mf
from sensors.data.dataset import WindowDataset
from sensors.data.recording import Channel, write_recording

LENGTHS = {0: {"a": 20, "b": 7, "c": 3}, 1: {"a": 11}}  # c is shorter than a window


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("ds")
    truth = {}
    for shard, eps in LENGTHS.items():
        rng = np.random.default_rng(shard)
        episodes = {}
        for ep, n in eps.items():
            chans = {
                "time": Channel(np.arange(n) / 10.0, "s", ("time",)),
                "v": Channel(rng.normal(size=(n, 2, 3)).astype(np.float32), "V", ("time", "row", "col")),
                "adc": Channel(rng.integers(0, 1000, size=(n,), dtype=np.int32), "counts", ("time",)),
                "force": Channel(rng.normal(size=(n, 2)), "N", ("time", "axis")),
            }
            episodes[ep] = chans
            truth[(shard, ep)] = {k: c.data for k, c in chans.items()}
        write_recording(mf.shard_path(d, shard), episodes, source="sim", config_json="{}", root_seed=0,
                        shard_index=shard, sensor_attrs={})
    return d, truth


def expected(truth, shard, ep, start, window, horizon=0):
    t = truth[(shard, ep)]
    x = np.concatenate([t["v"][start:start + window].reshape(window, -1),
                        t["adc"][start:start + window].reshape(window, -1)], axis=1).astype(np.float32)
    y = np.concatenate([t["force"][start + window - 1 + horizon].ravel(),
                        t["time"][start + window - 1 + horizon].ravel()]).astype(np.float32)
    return x, y


def test_exact_windows(data_dir):
    d, truth = data_dir
    ds = WindowDataset(d, inputs=["v", "adc"], targets=["force", "time"], window=4, stride=3)
    assert ds.n_input_features == 7 and ds.n_target_features == 3
    assert ds.input_slices == {"v": slice(0, 6), "adc": slice(6, 7)}
    # windows per episode: (n - 4)//3 + 1 -> a:6, b:2, c:0 | a:3
    assert len(ds) == 6 + 2 + 0 + 3
    order = [(0, "a", s) for s in range(0, 16, 3)] + [(0, "b", s) for s in (0, 3)] + \
            [(1, "a", s) for s in (0, 3, 6)]
    for i, (shard, ep, start) in enumerate(order):
        x, y = ds[i]
        assert x.dtype == torch.float32 and x.shape == (4, 7) and y.shape == (3,)
        ex, ey = expected(truth, shard, ep, start, 4)
        np.testing.assert_array_equal(x.numpy(), ex)
        np.testing.assert_array_equal(y.numpy(), ey)
        assert ds.locate(i) == (mf.shard_path(d, shard).resolve(), ep, start)
    np.testing.assert_array_equal(ds[-1][0].numpy(), expected(truth, 1, "a", 6, 4)[0])
    with pytest.raises(IndexError):
        ds[len(ds)]


def test_horizon_and_selection(data_dir):
    d, truth = data_dir
    ds = WindowDataset([mf.shard_path(d, 0)], inputs=["v", "adc"], targets=["force", "time"], window=5,
                       horizon=2, episodes=["shard-00000/b"])
    assert len(ds) == 7 - 5 - 2 + 1 == 1
    x, y = ds[0]
    ex, ey = expected(truth, 0, "b", 0, 5, horizon=2)
    np.testing.assert_array_equal(x.numpy(), ex)
    np.testing.assert_array_equal(y.numpy(), ey)
    ds2 = WindowDataset(d, inputs=["v", "adc"], targets=["force", "time"], window=2,
                        episodes=[(mf.shard_path(d, 1), "a")])
    assert len(ds2) == 10 and ds2.locate(0)[1] == "a"
    with pytest.raises(ValueError, match="not a time series|no channel|differ"):
        WindowDataset(d, inputs=["nope"], targets=["force"], window=2)
    with pytest.raises(ValueError, match="horizon"):
        WindowDataset(d, inputs=["v"], targets=["force"], window=2, horizon="first")


def test_pickle_drops_handles(data_dir):
    d, _ = data_dir
    ds = WindowDataset(d, inputs=["v"], targets=["force"], window=3)
    assert ds._handles == {}  # nothing open after construction
    ds[0]
    assert len(ds._handles) == 1
    clone = copy.deepcopy(ds)  # goes through __getstate__, as pickling to a DataLoader worker does
    assert clone._handles == {} and clone._pid is None
    np.testing.assert_array_equal(clone[5][0].numpy(), ds[5][0].numpy())
    ds.close()


def test_dataloader_two_workers(data_dir):
    d, truth = data_dir
    ds = WindowDataset(d, inputs=["v", "adc"], targets=["force", "time"], window=4, stride=1)
    ds[0]  # a handle open in the parent must not leak into the workers
    loader = DataLoader(ds, batch_size=5, num_workers=2, shuffle=False)
    xs, ys = zip(*loader)
    X, Y = torch.cat(xs), torch.cat(ys)
    assert X.shape == (len(ds), 4, 7)
    ref = [ds[i] for i in range(len(ds))]
    np.testing.assert_array_equal(X.numpy(), np.stack([r[0].numpy() for r in ref]))
    np.testing.assert_array_equal(Y.numpy(), np.stack([r[1].numpy() for r in ref]))
    ex, ey = expected(truth, 1, "a", 7, 4)
    np.testing.assert_array_equal(X[-1].numpy(), ex)

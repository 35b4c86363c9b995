"""Generation end to end: determinism, force balance, resumption after a crash, Dataset windows."""

import numpy as np
import pytest

from scenes import load_scene
from sensors.data.dataset import WindowDataset
from sensors.data.manifest import read_manifest, shard_path
from sensors.data.recording import Recording
from simulate.generation import run

FAST = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=6", "pad.taxels_y=6",
        "generation.episodes=4", "generation.episodes_per_shard=2", "generation.root_seed=11"]


@pytest.fixture(scope="module")
def cfg():
    return load_scene("cnt_pdms", FAST)


def _read_all(path):
    with Recording(path) as rec:
        return {ep: {ch: rec.read(ep, ch) for ch in rec.channels(ep)} for ep in rec.episode_ids}


def test_generation_is_deterministic_and_balanced(cfg, tmp_path):
    run.generate(cfg, tmp_path / "a")
    run.generate(cfg, tmp_path / "b")
    a, b = _read_all(shard_path(tmp_path / "a", 1)), _read_all(shard_path(tmp_path / "b", 1))
    for ep in a:
        for ch in a[ep]:
            np.testing.assert_array_equal(a[ep][ch], b[ep][ch])
    area = cfg.pad.size_x_m * cfg.pad.size_y_m / cfg.pad.n_taxels
    for ep in a.values():
        # Winkler pressure integrates back to MuJoCo's normal contact force
        np.testing.assert_allclose(ep["pressure"].sum(-1) * area, ep["contact_force"][:, 2], rtol=1e-4, atol=1e-4)
        # the label is the viscoelastic stress integrated over the taxels
        np.testing.assert_allclose(ep["force_taxel"].sum(-1), ep["force"], rtol=1e-4, atol=1e-5)
    m = read_manifest(tmp_path / "a")
    seeds = [s for sh in m["shards"] for s in sh["episode_seeds"]]
    assert len(set(seeds)) == 4


def test_killed_generation_resumes_at_first_missing_shard(cfg, tmp_path, monkeypatch):
    out = tmp_path / "ds"
    real = run.write_shard
    calls = []

    def crash_on_second(c, o, shard, sensor, mjcf):
        calls.append(shard)
        if shard == 1:
            raise KeyboardInterrupt("killed")
        return real(c, o, shard, sensor, mjcf)

    monkeypatch.setattr(run, "write_shard", crash_on_second)
    with pytest.raises(KeyboardInterrupt):
        run.generate(cfg, out)
    assert shard_path(out, 0).is_file()
    assert not shard_path(out, 1).exists() and not (out / "manifest.json").exists()
    assert not list(out.glob("*.tmp"))
    mtime0 = shard_path(out, 0).stat().st_mtime_ns
    calls.clear()
    monkeypatch.setattr(run, "write_shard", lambda *a: (calls.append(a[2]), real(*a))[1])
    run.generate(cfg, out)
    assert calls == [1]  # only the missing shard was generated
    assert shard_path(out, 0).stat().st_mtime_ns == mtime0
    assert read_manifest(out)["n_shards"] == 2


def test_window_dataset_over_generated_data(cfg, tmp_path):
    out = tmp_path / "ds"
    run.generate(cfg, out)
    ds = WindowDataset(out, inputs=["resistance_measured"], targets=["force"], window=50, stride=10)
    x, y = ds[3]
    assert tuple(x.shape) == (50, 1) and tuple(y.shape) == (1,)
    assert len(ds) > 4

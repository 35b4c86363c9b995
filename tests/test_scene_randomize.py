"""Scene `randomize` section: per-episode draws from the episode seed, recorded, applied; none = unchanged."""

import numpy as np
import pytest
from pydantic import ValidationError

from scenes import config_json, load_scene
from sensors.data.manifest import shard_path
from sensors.data.recording import Recording
from simulate.generation import run

FAST = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=6", "pad.taxels_y=6",
        "generation.episodes=3", "generation.episodes_per_shard=3", "generation.root_seed=5"]
RAND = {"params": {"sensor.electronics.amp_gain": {"kind": "loguniform", "low": 100.0, "high": 400.0},
                   "placement.x_m": {"kind": "uniform", "low": -0.004, "high": 0.004}}}


def _scene(rand=None):
    cfg = load_scene("cnt_pdms", FAST)
    if rand is None:
        return cfg
    return type(cfg).model_validate({**cfg.model_dump(), "randomize": rand})


def _read(path):
    with Recording(path) as rec:
        return {ep: (dict(rec.episode_attrs(ep)), {c: rec.read(ep, c) for c in rec.channels(ep)}) for ep in rec.episode_ids}


def test_draws_are_seeded_recorded_and_applied(tmp_path):
    cfg = _scene(RAND)
    run.generate(cfg, tmp_path / "a")
    run.generate(cfg, tmp_path / "b")
    a, b = _read(shard_path(tmp_path / "a", 0)), _read(shard_path(tmp_path / "b", 0))
    gains = []
    for ep in a:
        at, ch = a[ep]
        assert at["rand.sensor.electronics.amp_gain"] == b[ep][0]["rand.sensor.electronics.amp_gain"]
        for c in ch:
            np.testing.assert_array_equal(ch[c], b[ep][1][c])
        assert 100.0 <= at["rand.sensor.electronics.amp_gain"] <= 400.0
        assert at["offset_xy_m"][0] == pytest.approx(at["rand.placement.x_m"])
        gains.append(at["rand.sensor.electronics.amp_gain"])
    assert len(set(gains)) == 3  # one draw per episode
    # the drawn gain is the one the chain used, and an episode does not depend on its batch: one episode
    # alone (a fixed-gain scene, the same protocol) equals its place in the batch of three
    ep = sorted(a)[1]
    seed = int(a[ep][0]["seed"])
    proto = run.episode_protocols(cfg, [seed], [1])[0]
    assert proto.params["randomized"]["sensor.electronics.amp_gain"] == a[ep][0]["rand.sensor.electronics.amp_gain"]
    fixed = type(cfg).model_validate({**cfg.model_dump(), "randomize": None,
                                      "sensor": {**cfg.sensor.model_dump(), "electronics": {
                                          **cfg.sensor.electronics.model_dump(), "amp_gain": gains[1]}}})
    out = {}
    for pos, _, arrays in run.simulate_slices(fixed, [seed], run.make_sensor(fixed, "warp", "cpu"), protos=[proto]):
        out = run.episode_channels(arrays, 0)
    np.testing.assert_array_equal(out["adc"].data, a[ep][1]["adc"])


def test_empty_randomize_leaves_scene_json_unchanged():
    assert config_json(_scene({"params": {}})) == config_json(_scene())
    assert run.config_sha256(_scene({"params": {}})) == run.config_sha256(_scene())


@pytest.mark.parametrize("bad", [
    {"params": {"indenter.size_x_m": {"kind": "uniform", "low": 0.005, "high": 0.01}}},  # shared MuJoCo model
    {"params": {"sensor.electronics.amp_gain": {"kind": "uniform", "low": -1.0, "high": 2.0}}},  # out of the field's bounds
    {"params": {"sensor.nope": {"kind": "uniform", "low": 0.0, "high": 1.0}}},
    {"params": {"placement.x_m": {"kind": "uniform", "low": -1.0, "high": 1.0}}},  # off the pad
    {"params": {"sensor.electronics.amp_gain": {"kind": "uniform", "low": 3.0, "high": 2.0}}},
])
def test_bad_randomize_is_refused(bad):
    with pytest.raises(ValidationError):
        _scene(bad)


@pytest.mark.parametrize("field", ["low", "high", "values"])
@pytest.mark.parametrize("value", [float("inf"), float("-inf"), float("nan"), 1e30, -1e30])
def test_distribution_floats_are_finite_and_bounded(field, value):
    d = {"kind": "uniform", "low": 0.0, "high": 1.0}
    d = {"kind": "choice", "values": [value]} if field == "values" else {**d, field: value}
    with pytest.raises(ValidationError):
        _scene({"params": {"sensor.electronics.amp_gain": d}})

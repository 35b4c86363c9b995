"""The manifest's content hash: equal for equal data (two identical runs), different for other data, printed by
inspect (issue 17, item 8)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from sensors.data.manifest import read_manifest
from sensors.data.recording import Recording

runner = CliRunner()
FAST = ["--set", "protocol.frequencies_hz=[2.0]", "--set", "protocol.cycles=1", "--set", "pad.taxels_x=5",
        "--set", "pad.taxels_y=5", "--set", "generation.episodes_per_shard=2", "--episodes", "3"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("repro")
    out = {}
    for key, seed in (("a", 5), ("b", 5), ("c", 6)):
        res = runner.invoke(app, ["generate", "cnt_pdms", "-o", str(root / key), "--seed", str(seed)] + FAST)
        assert res.exit_code == 0, res.output
        out[key] = root / key
    return out


def test_identical_runs_have_the_same_content_hash(runs):
    a, b = read_manifest(runs["a"]), read_manifest(runs["b"])
    assert a["content_sha256"] and len(a["content_sha256"]) == 64
    assert a["content_sha256"] == b["content_sha256"]
    assert [s["content_sha256"] for s in a["shards"]] == [s["content_sha256"] for s in b["shards"]]
    with Recording(runs["a"] / "shard-00000.h5") as ra, Recording(runs["b"] / "shard-00000.h5") as rb:
        assert ra.compute_content_sha256() == ra.content_sha256 == rb.compute_content_sha256()


def test_another_seed_has_another_content_hash(runs):
    a, c = read_manifest(runs["a"]), read_manifest(runs["c"])
    assert a["content_sha256"] != c["content_sha256"]
    assert all(x["content_sha256"] != y["content_sha256"] for x, y in zip(a["shards"], c["shards"]))


def test_timestamps_do_not_enter_the_hash(runs, tmp_path):
    import shutil

    import h5py

    p = tmp_path / "s.h5"
    shutil.copy(runs["a"] / "shard-00000.h5", p)
    with h5py.File(p, "r+") as f:
        f.attrs["created_utc"] = "1999-01-01T00:00:00Z"
        f.attrs["generator_commit"] = "0" * 40
    with Recording(p) as r, Recording(runs["a"] / "shard-00000.h5") as r0:
        assert r.compute_content_sha256() == r0.content_sha256
    with h5py.File(p, "r+") as f:
        d = f["episodes/ep-000000/force"]
        d[3] = d[3] + 1.0  # one number changed
    with Recording(p) as r:
        assert r.compute_content_sha256() != r.content_sha256


def test_inspect_prints_the_content_hash(runs):
    m = read_manifest(runs["a"])
    res = runner.invoke(app, ["inspect", str(runs["a"])])
    assert res.exit_code == 0 and f"content_sha256 {m['content_sha256']}" in res.output
    res = runner.invoke(app, ["inspect", str(runs["a"] / "shard-00000.h5")])
    assert res.exit_code == 0 and f"content_sha256 {m['shards'][0]['content_sha256']}" in res.output


def test_manifest_still_reads_without_content_hash(runs, tmp_path):
    """A manifest from before content hashes: inspect says so instead of failing."""
    import shutil

    d = tmp_path / "old"
    shutil.copytree(runs["a"], d)
    m = json.loads((d / "manifest.json").read_text())
    del m["content_sha256"]
    (d / "manifest.json").write_text(json.dumps(m))
    res = runner.invoke(app, ["inspect", str(d)])
    assert res.exit_code == 0 and "content_sha256 -" in res.output


def test_digest_attributes_made_in_memory_equal_the_ones_read_back(tmp_path):
    """The writer hashes an episode's attributes as a reader decodes them without reading them back
    (`_decoded_attrs`): for every kind of value it stores, the same Python values (and types) as `_get_attrs`."""
    import h5py
    import numpy as np

    from sensors.data.recording import _decoded_attrs, _encode_attrs, _get_attrs, _write_attrs

    attrs = {"i": 7, "big": 2**63 + 5, "neg": -3, "f": 0.1, "f32": np.float32(0.1), "f16": np.float16(1.5),
             "nan": float("nan"), "b": True, "nb": np.bool_(False), "s": "pad ü", "ns": np.str_("x"),
             "c": np.complex128(1 + 2j), "arr": np.arange(4, dtype=np.int16), "farr": np.array([0.5, -1.0]),
             "barr": np.array([True, False]), "zero_d": np.array(2.5), "lst": [1.0, 2.0], "ilst": (1, 2, 3),
             "empty": [], "d": {"a": [1, "b"]}, "names": ["x", "y"], "i64": np.int64(-9), "u8": np.uint8(200)}
    enc = _encode_attrs(attrs, "test")
    with h5py.File(tmp_path / "a.h5", "w") as f:
        g = f.create_group("ep")
        _write_attrs(g, enc)
        back = _get_attrs(g)
    mem = _decoded_attrs(enc)
    assert sorted(mem) == sorted(back)
    for k in back:
        assert type(mem[k]) is type(back[k]), k
        if isinstance(back[k], np.ndarray):
            assert mem[k].dtype == back[k].dtype and mem[k].shape == back[k].shape, k
            np.testing.assert_array_equal(mem[k], back[k])
        elif isinstance(back[k], float) and np.isnan(back[k]):
            assert np.isnan(mem[k])
        else:
            assert mem[k] == back[k], k

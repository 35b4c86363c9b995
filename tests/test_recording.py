"""Recording format, atomic writes, resumption, manifest, splits and seeds."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from sensors.data import manifest as mf
from sensors.data import recording as rc
from sensors.data.recording import (
    FORMAT,
    Channel,
    Recording,
    RecordingError,
    write_recording,
)

CONFIG = json.dumps({"family": "cnt_pdms", "sample_rate_hz": 100.0}, sort_keys=True)
CONFIG_SHA = __import__("hashlib").sha256(CONFIG.encode()).hexdigest()


def make_episode(rng: np.random.Generator, n: int = 300) -> dict[str, Channel]:
    return {
        "time": Channel(np.arange(n) / 100.0, "s", ("time",)),
        "force": Channel(rng.normal(size=(n, 6, 6, 3)).astype(np.float32), "N", ("time", "row", "col", "axis"),
                         "ground-truth force per taxel"),
        "adc": Channel(rng.integers(0, 2**14, size=(n, 36), dtype=np.uint16), "counts", ("time", "taxel")),
        "total": Channel(rng.normal(size=n), "N", ("time",)),
        "gain": Channel(np.float64(2.5), "1", ()),
    }


def write_shard(path, n_eps=3, seed=0, **kw):
    rng = np.random.default_rng(seed)
    eps = {f"ep-{k}": make_episode(rng) for k in range(n_eps)}
    args = dict(
        source="sim",
        config_json=CONFIG,
        root_seed=7,
        shard_index=0,
        sensor_attrs={"family": "cnt_pdms", "adc": {"bits": 14, "range_v": [0.0, 3.3]}},
    )
    args.update(kw)
    return write_recording(path, eps, **args), eps


@pytest.mark.parametrize("compression", ["lzf", "gzip", "none"])
def test_round_trip(tmp_path, compression):
    rng = np.random.default_rng(1)
    eps = {f"ep{k}": make_episode(rng, n=257 + k) for k in (10, 2, 1)}  # T not a multiple of 256
    taxels = rng.uniform(0, 0.03, size=(36, 2))
    p = write_recording(
        tmp_path / "r.h5",
        eps,
        source="real",
        config_json=CONFIG,
        root_seed=2**64 - 1,
        shard_index=3,
        sensor_attrs={"family": "ntype", "taxel_pos_m": taxels, "adc": {"bits": 14}, "sample_rate_hz": 100.0},
        mjcf="<mujoco><worldbody/></mujoco>",
        episode_attrs={"ep2": {"seed": 12345678901234567890, "frequency_hz": 100.0, "n_samples": 259}},
        extra_attrs={"port": "/dev/ttyACM0", "frames_dropped": 0},
        compression=compression,
    )
    assert p == tmp_path / "r.h5" and not (tmp_path / "r.h5.tmp").exists()
    with Recording(p) as r:  # the config hash alone (a shard check), before and after every attribute is read
        assert r.config_sha256 == CONFIG_SHA and "attrs" not in r.__dict__
    with Recording(p) as r:
        a = r.attrs
        assert r.config_sha256 == CONFIG_SHA
        assert a["format"] == FORMAT and a["format_version"] == rc.FORMAT_VERSION
        assert a["source"] == "real" and a["root_seed"] == 2**64 - 1 and a["shard_index"] == 3
        assert a["config_json"] == CONFIG and a["config_sha256"] == CONFIG_SHA
        assert a["generator"].startswith("piezotwin ") and a["version_numpy"] == np.__version__
        assert a["version_h5py"] == h5py.__version__ and a["created_utc"].endswith("Z")
        assert a["port"] == "/dev/ttyACM0" and a["frames_dropped"] == 0
        assert r.config == json.loads(CONFIG)
        assert r.mjcf == "<mujoco><worldbody/></mujoco>"
        s = r.sensor_attrs
        assert s["family"] == "ntype" and s["adc"] == {"bits": 14} and s["sample_rate_hz"] == 100.0
        np.testing.assert_array_equal(s["taxel_pos_m"], taxels)
        assert r.episode_ids == ["ep1", "ep2", "ep10"]  # natural order
        assert r.episode_attrs("ep2") == {"seed": 12345678901234567890, "frequency_hz": 100.0, "n_samples": 259}
        assert r.episode_attrs("ep1") == {}
        for ep, chans in eps.items():
            assert r.channels(ep) == sorted(chans)
            for name, ch in chans.items():
                got = r.read(ep, name)
                assert got.dtype == ch.data.dtype and got.shape == ch.data.shape
                assert got.tobytes() == ch.data.tobytes()  # bit-identical
                assert r.units(ep, name) == ch.units and r.dim_names(ep, name) == ch.dim_names
                assert r.description(ep, name) == ch.description
        np.testing.assert_array_equal(r.read("ep10", "force", slice(5, 9)), eps["ep10"]["force"].data[5:9])
        ds = r._f["episodes/ep10/force"]
        if compression == "none":
            assert ds.compression is None
        else:
            assert ds.compression == compression and ds.shuffle
            assert ds.chunks == ds.shape  # 10 kB: the whole episode in one chunk
        summ = r.summary()
    assert summ["n_episodes"] == 3 and summ["channels"]["force"]["units"] == "N"
    assert summ["duration_s"] == pytest.approx((258 + 259 + 267) / 100.0)
    allf = np.concatenate([c["force"].data.ravel() for c in eps.values()])
    assert summ["channels"]["force"]["min"] == pytest.approx(float(allf.min()))
    assert summ["channels"]["force"]["max"] == pytest.approx(float(allf.max()))
    assert summ["channels"]["force"]["frame_shape"] == (6, 6, 3)
    assert rc.read_recording_summary(p)["channels"]["adc"]["max"] == max(
        int(c["adc"].data.max()) for c in eps.values()
    )


def test_stored_summary_equals_reading_the_data_and_stays_out_of_the_content_hash(tmp_path):
    # the writer's summary (from the arrays it writes) is what reading every dataset gives, including a channel
    # with NaN and inf (finite range only), one with no finite value, an integer and a 0-d channel; it is not part
    # of the content hash (derived from the hashed data), so removing it leaves the hash as it was
    rng = np.random.default_rng(3)
    eps = {}
    for k, n in enumerate((40, 7, 1)):
        e = make_episode(rng, n=n)
        pos = rng.normal(size=(n, 2))
        pos[::3] = np.nan
        pos[0, 0] = np.inf
        e["position"] = Channel(pos, "m", ("time", "xy"))
        e["dead"] = Channel(np.full(n, np.nan, np.float32), "V", ("time",))
        eps[f"ep{k}"] = e
    p = write_recording(tmp_path / "s.h5", eps, source="sim", config_json=CONFIG, root_seed=1, shard_index=0,
                        sensor_attrs={"family": "cnt_pdms"})
    with Recording(p) as r:
        read = r.summary()
        stored = r.summary(from_data=False)
        assert rc.SUMMARY_ATTR in r.attrs
        assert r.compute_content_sha256() == r.content_sha256
    assert stored == read
    assert read["channels"]["dead"]["min"] is None and read["channels"]["dead"]["max"] is None
    finite = np.concatenate([e["position"].data.ravel() for e in eps.values()])
    finite = finite[np.isfinite(finite)]
    assert read["channels"]["position"]["max"] == float(finite.max())
    assert read["n_samples"] == 48 and read["channels"]["gain"]["n_samples"] == 3
    with h5py.File(p, "r+") as f:  # as written by an older piezotwin: no stored summary
        h = f.attrs["content_sha256"]
        del f.attrs[rc.SUMMARY_ATTR]
    with Recording(p) as r:
        assert r.compute_content_sha256() == h
        assert r.summary(from_data=False) == read  # read from the data where none is stored


def test_chunk_len_divides_when_possible():
    assert rc._chunk_len(3000, 900) == 1000  # 2.7 MB: <= 1 MiB (1165 frames), the longest that divides 3000
    assert rc._chunk_len(100, 900) == 100  # fits: the whole series
    assert rc._chunk_len(5142, 4) == 5142  # fabric_1's narrow frames: one chunk per episode, not 21
    c = rc._chunk_len(3001, 900)  # no divisor near the cap (3001 is prime): three equal parts, <= 1 MiB
    assert c == 1001 and c * 900 <= 1 << 20
    assert rc._chunk_len(1505, 1152) == 753  # velostat's shear: two chunks, not 910 + 595 (stored as 910)
    assert rc._chunk_len(10_000, 4_000_000) == 1  # huge frames: one frame per chunk


def test_validation_errors(tmp_path):
    with pytest.raises(ValueError, match="dim_names"):
        Channel(np.zeros((4, 3)), "N", ("time",))
    ch = Channel(np.zeros((4, 3)), "N", ("time", "taxel"))
    ch.data = np.zeros((4, 3, 2))  # mutated after construction: caught at write time
    with pytest.raises(ValueError, match="dim_names"):
        write_recording(tmp_path / "a.h5", {"e": {"f": ch}}, source="sim", config_json="{}",
                        root_seed=0, shard_index=0, sensor_attrs={})
    with pytest.raises(ValueError, match="empty"):
        write_recording(tmp_path / "a.h5", {}, source="sim", config_json="{}",
                        root_seed=0, shard_index=0, sensor_attrs={})
    good = {"f": Channel(np.zeros(4), "N", ("time",))}
    for bad_id in ["", "a/b", "..", ".hidden", "a b", 3]:
        with pytest.raises(ValueError, match="episode id"):
            write_recording(tmp_path / "a.h5", {bad_id: good}, source="sim", config_json="{}",
                            root_seed=0, shard_index=0, sensor_attrs={})
    with pytest.raises(ValueError, match="source"):
        write_recording(tmp_path / "a.h5", {"e": good}, source="fake", config_json="{}",
                        root_seed=0, shard_index=0, sensor_attrs={})
    assert not list(tmp_path.iterdir())  # nothing written by any refused call


def test_crash_mid_write_leaves_no_file(tmp_path, monkeypatch):
    calls = {"n": 0}
    real = rc._write_channel

    def flaky(*a, **k):
        calls["n"] += 1
        if calls["n"] == 4:
            raise RuntimeError("simulated crash")
        return real(*a, **k)

    monkeypatch.setattr(rc, "_write_channel", flaky)
    target = mf.shard_path(tmp_path, 0)
    with pytest.raises(RuntimeError, match="simulated crash"):
        write_shard(target)
    assert calls["n"] == 4
    assert not target.exists() and not list(tmp_path.iterdir())  # tmp removed too
    assert mf.first_missing_shards(tmp_path, 2, CONFIG_SHA) == [0, 1]


def test_killed_process_leaves_only_tmp(tmp_path):
    """A hard kill (no exception handling) mid-write leaves a .tmp, never a final file."""
    script = textwrap.dedent(
        f"""
        import os, numpy as np
        from sensors.data import recording as rc
        real = rc.RecordingWriter.add_episode
        n = [0]
        def die(*a, **k):
            n[0] += 1
            if n[0] == 3:  # two episodes in the file
                os._exit(9)
            return real(*a, **k)
        rc.RecordingWriter.add_episode = die
        eps = {{"e%d" % i: {{"x": rc.Channel(np.ones((100, 4)), "V", ("time", "c"))}} for i in range(3)}}
        rc.write_recording({str(mf.shard_path(tmp_path, 1))!r}, eps, source="sim", config_json={CONFIG!r},
                           root_seed=1, shard_index=1, sensor_attrs={{}})
        """
    )
    write_shard(mf.shard_path(tmp_path, 0))
    proc = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parents[1])
    assert proc.returncode == 9
    assert not mf.shard_path(tmp_path, 1).exists()
    assert (tmp_path / "shard-00001.h5.tmp").exists()
    assert mf.first_missing_shards(tmp_path, 3, CONFIG_SHA) == [1, 2]
    write_shard(mf.shard_path(tmp_path, 1), shard_index=1)  # the rerun overwrites the stale tmp
    assert mf.first_missing_shards(tmp_path, 3, CONFIG_SHA) == [2]
    assert not (tmp_path / "shard-00001.h5.tmp").exists()


def test_truncated_garbage_foreign_files_are_incomplete(tmp_path):
    good, _ = write_shard(mf.shard_path(tmp_path, 0))
    assert mf.is_shard_complete(good, CONFIG_SHA)
    assert mf.is_shard_complete(good, None)
    assert not mf.is_shard_complete(good, "0" * 64)  # another config
    data = good.read_bytes()
    mf.shard_path(tmp_path, 1).write_bytes(data[: len(data) // 2])  # truncated
    mf.shard_path(tmp_path, 2).write_bytes(b"\x89HDF\r\n\x1a\n" + b"garbage" * 100)
    with h5py.File(mf.shard_path(tmp_path, 3), "w") as f:  # valid HDF5, not a recording
        f["x"] = np.arange(3)
    mf.shard_path(tmp_path, 4).write_bytes(b"")
    assert mf.first_missing_shards(tmp_path, 6, CONFIG_SHA) == [1, 2, 3, 4, 5]


def test_foreign_hdf5_raises_recording_error(tmp_path):
    p = tmp_path / "other.h5"
    with h5py.File(p, "w") as f:
        f["data"] = np.arange(3)
    with pytest.raises(RecordingError, match="not a piezotwin-recording file") as ei:
        Recording(p)
    assert "\n" not in str(ei.value) and "data" in str(ei.value)
    with h5py.File(p, "a") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(RecordingError, match="'something-else'"):
        Recording(p)
    txt = tmp_path / "notes.h5"
    txt.write_text("hello")
    with pytest.raises(RecordingError, match="not a readable HDF5 file"):
        Recording(txt)
    newer, _ = write_shard(tmp_path / "new.h5")
    with h5py.File(newer, "a") as f:
        f.attrs["format_version"] = rc.FORMAT_VERSION + 1
    with pytest.raises(RecordingError, match="newer"):
        Recording(newer)
    assert issubclass(RecordingError, ValueError)


def test_manifest_round_trip_and_verify(tmp_path):
    for i in range(3):
        eps = {}
        rng = np.random.default_rng(i)
        for k in range(4):
            eps[f"ep-{k}"] = make_episode(rng, n=50)
        seeds = {f"ep-{k}": {"seed": mf.episode_seed(7, i * 4 + k)} for k in range(4)}
        write_recording(mf.shard_path(tmp_path, i), eps, source="sim", config_json=CONFIG, root_seed=7,
                        shard_index=i, sensor_attrs={}, episode_attrs=seeds,
                        extra_attrs={"shard_seed": mf.shard_seed(7, i)})
    path = mf.build_manifest(tmp_path, name="demo", n_shards=3, episodes_per_shard=4,
                             config_sha256=CONFIG_SHA, root_seed=7)
    assert path == tmp_path / "manifest.json" and not (tmp_path / "manifest.json.tmp").exists()
    m = mf.read_manifest(tmp_path)
    assert m["format"] == mf.MANIFEST_FORMAT and m["name"] == "demo" and m["root_seed"] == 7
    assert m["n_shards"] == 3 and m["total_episodes"] == 12 and m["episodes_per_shard"] == 4
    s1 = m["shards"][1]
    assert s1["file"] == "shard-00001.h5" and s1["sha256"] == mf.file_sha256(mf.shard_path(tmp_path, 1))
    assert s1["bytes"] == mf.shard_path(tmp_path, 1).stat().st_size
    assert s1["episode_seeds"] == [mf.episode_seed(7, 4 + k) for k in range(4)]
    assert s1["shard_seed"] == mf.shard_seed(7, 1)
    sp = m["splits"]
    all_ids = sp["train"] + sp["valid"] + sp["test"]
    assert len(all_ids) == len(set(all_ids)) == 12 and "shard-00002/ep-3" in all_ids
    assert mf.verify_manifest(tmp_path) == []
    with open(mf.shard_path(tmp_path, 2), "r+b") as f:  # flip a byte
        f.seek(100)
        b = f.read(1)
        f.seek(100)
        f.write(bytes([b[0] ^ 0xFF]))
    assert mf.verify_manifest(tmp_path) == ["shard-00002.h5: sha256 mismatch"]
    (tmp_path / "manifest.json").write_text('{"format": "nope"}')
    with pytest.raises(mf.ManifestError, match="nope"):
        mf.read_manifest(tmp_path)
    with pytest.raises(mf.ManifestError, match="no manifest"):
        mf.read_manifest(tmp_path / "nowhere")


def test_manifest_trusts_this_runs_writers_and_checks_the_rest(tmp_path, monkeypatch):
    """build_manifest with the writers' entries (`described`) opens none of those shards again and writes the same
    manifest; an entry whose file changed size, or of another config, is checked and described from the file."""
    for i in range(3):
        rng = np.random.default_rng(i)
        eps = {f"ep-{k}": make_episode(rng, n=20) for k in range(2)}
        write_recording(mf.shard_path(tmp_path, i), eps, source="sim", config_json=CONFIG, root_seed=7,
                        shard_index=i, sensor_attrs={}, episode_attrs={f"ep-{k}": {"seed": k} for k in range(2)})
    kw = dict(name="demo", n_shards=3, episodes_per_shard=2, config_sha256=CONFIG_SHA, root_seed=7)
    mf.build_manifest(tmp_path, **kw)

    def manifest():  # all but the time it was written
        return {k: v for k, v in mf.read_manifest(tmp_path).items() if k != "created_utc"}

    want = manifest()
    assert want["summary"]["n_samples"] == 3 * 2 * 20  # the shards' stored summaries, merged
    described = {i: mf.describe_shard(mf.shard_path(tmp_path, i)) for i in range(3)}  # as the writers make them
    assert all("summary" in d for d in described.values())
    opened = []
    real_complete, real_describe = mf.is_shard_complete, mf.describe_shard
    monkeypatch.setattr(mf, "is_shard_complete", lambda p, c, **k: opened.append(Path(p).name) or real_complete(p, c, **k))
    monkeypatch.setattr(mf, "describe_shard", lambda p, **k: opened.append(Path(p).name) or real_describe(p, **k))
    mf.build_manifest(tmp_path, described=described, **kw)
    assert opened == [] and manifest() == want
    stale = {**described, 1: {**described[1], "bytes": described[1]["bytes"] + 1},
             2: {**described[2], "config_sha256": "0" * 64}}
    mf.build_manifest(tmp_path, described=stale, **kw)
    assert sorted(opened) == sorted(["shard-00001.h5", "shard-00002.h5"] * 2)
    assert manifest() == want


def test_write_manifest_rejects_overlapping_splits(tmp_path):
    shards = [{"file": "shard-00000.h5", "sha256": "x", "bytes": 1, "episodes": ["a", "b"],
               "episode_seeds": [1, 2], "shard_seed": None}]
    with pytest.raises(ValueError, match="overlaps"):
        mf.write_manifest(tmp_path, name="d", root_seed=0, episodes_per_shard=2, config_sha256="c",
                          shards=shards, splits={"train": ["shard-00000/a"], "valid": ["shard-00000/a"],
                                                 "test": []})
    assert not (tmp_path / "manifest.json").exists()


def test_splits_deterministic_disjoint():
    ids = [f"shard-{s:05d}/ep-{k}" for s in range(5) for k in range(20)]
    a = mf.make_splits(ids, seed=3)
    b = mf.make_splits(list(reversed(ids)), seed=3)  # input order does not matter
    assert a == b
    assert len(a["valid"]) == 10 and len(a["test"]) == 10 and len(a["train"]) == 80
    assert not set(a["train"]) & set(a["valid"]) and not set(a["train"]) & set(a["test"])
    assert not set(a["valid"]) & set(a["test"])
    assert sorted(a["train"] + a["valid"] + a["test"]) == sorted(ids)
    assert mf.make_splits(ids, seed=4) != a
    with pytest.raises(ValueError):
        mf.make_splits(ids, seed=0, fractions=(0.5, 0.1, 0.1))


def test_episode_seeds_stable_and_count_independent():
    s = mf.derive_seeds(42, 10)
    assert s == [mf.episode_seed(42, k) for k in range(10)]
    assert mf.derive_seeds(42, 1000)[:10] == s  # more episodes: same first seeds
    assert len(set(mf.derive_seeds(42, 1000))) == 1000
    assert mf.derive_seeds(43, 10) != s
    # pinned: a change of derivation would silently change every dataset
    assert mf.episode_seed(42, 5) == 661281422688282993
    assert mf.episode_seed(0, 0) == 8668861027912758289
    assert all(isinstance(x, int) and 0 <= x < 2**64 for x in s)
    assert mf.shard_seed(42, 0) not in s


def test_natural_order_fast_path_equals_the_general_key():
    """Dataset ids (same non-digit parts) are ordered by numpy; the order equals the per-id natural key with
    ties broken by the text, and id sets it cannot take (other shapes, digit runs beyond int64) fall back."""
    import random

    from sensors.data.manifest import _natural_order
    from sensors.data.recording import _natural_key

    general = lambda ids: sorted(ids, key=lambda e: (_natural_key(e), e))
    rng = random.Random(1)
    same_shape = [f"shard-{rng.randrange(30):05d}.h5/ep-{rng.randrange(10**6):0{rng.choice([1, 6])}d}" for _ in range(3000)]
    cases = [same_shape, ["ep-10", "ep-9", "ep-09", "ep-1"], ["a2b", "a10b", "b1", "x"], ["s/e-99999999999999999999", "s/e-3"]]
    for ids in cases:
        rng.shuffle(ids)
        assert _natural_order(ids) == general(ids)
    assert _natural_order(["ep-10", "ep-9"]) == ["ep-9", "ep-10"]  # numeric, not text order


@pytest.mark.parametrize("comp", ["zstd", "lz4"])
def test_blosc2_compressions_round_trip(tmp_path, comp):
    """Blosc2 (hdf5plugin) codecs: data back bit for bit, smaller than none, the same bytes when written twice."""
    from sensors.data.recording import Channel, Recording, write_recording

    rng = np.random.default_rng(0)
    ch = {"pressure": Channel(rng.normal(size=(500, 36)).astype(np.float32).cumsum(0), "Pa", ("time", "taxel"), ""),
          "time": Channel(np.arange(500) / 100.0, "s", ("time",), "")}
    paths = [write_recording(tmp_path / f"{comp}{i}.h5", {"ep-000000": ch}, source="sim", config_json="{}", root_seed=0,
                             shard_index=0, sensor_attrs={"family": "cnt_pdms"}, compression=comp) for i in range(2)]
    none = write_recording(tmp_path / "none.h5", {"ep-000000": ch}, source="sim", config_json="{}", root_seed=0,
                           shard_index=0, sensor_attrs={"family": "cnt_pdms"}, compression="none")
    with Recording(paths[0]) as rec:
        np.testing.assert_array_equal(rec.read("ep-000000", "pressure"), ch["pressure"].data)
        np.testing.assert_array_equal(rec.read("ep-000000", "time"), ch["time"].data)
    assert paths[0].stat().st_size < none.stat().st_size


@pytest.mark.parametrize("compression", ["lzf", "lz4"])
def test_files_of_the_earlier_storage_read_the_same(tmp_path, monkeypatch, compression):
    """Shards written before session 11 (HDF5's earliest object formats, chunks of <= 256 frames) read back as the
    same recording: same data, attributes and content hash; the 1.10 formats take fewer bytes for short episodes."""
    new, eps = write_shard(tmp_path / "new.h5", compression=compression)
    monkeypatch.setattr(rc, "_LIBVER", ("earliest", "latest"))
    monkeypatch.setattr(rc, "_CHUNK_MAX_BYTES", 256 * 36 * 2)  # 256 frames of the (n, 36) uint16 channel
    monkeypatch.setattr(rc, "TAXEL_BLOCK", 0)  # whole frames per chunk (taxel blocks came in session 18)
    monkeypatch.setattr(rc, "_TEMPLATES", type(rc._TEMPLATES)())  # no template of the new storage
    old, _ = write_shard(tmp_path / "old.h5", compression=compression)
    with h5py.File(old, "r") as f:
        assert f["episodes/ep-0/adc"].chunks == (150, 36)  # the earlier layout: 300 frames in two chunks
    with Recording(old) as a, Recording(new) as b:
        assert a.episode_ids == b.episode_ids == list(eps)
        for ep in eps:
            assert a.episode_attrs(ep) == b.episode_attrs(ep)
            for name in eps[ep]:
                assert a.read(ep, name).tobytes() == b.read(ep, name).tobytes() == eps[ep][name].data.tobytes()
        assert a.compute_content_sha256() == b.compute_content_sha256() == a.content_sha256 == b.content_sha256
    assert new.stat().st_size < old.stat().st_size


@pytest.mark.parametrize("compression", ["lzf", "lz4", "none"])
@pytest.mark.parametrize("fast", [True, False])
def test_zero_chunks_are_not_stored_and_read_back_the_same(tmp_path, monkeypatch, compression, fast):
    """A time series' all-zero chunks are left unwritten (HDF5 reads them as the fill value 0): the data read back
    are the same bytes (-0.0 and NaN stay, being nonzero bytes), the content hash and stored summary are those of
    writing every chunk, and the file is smaller. Both write paths: the episode template (fast) and the general one
    (an episode with an empty channel)."""
    monkeypatch.setattr(rc, "_CHUNK_MAX_BYTES", 64 * 8 * 4)  # 64 frames of (8,) float32 per chunk
    n = 337  # no divisor near 64 frames: six chunks of 57, the last one short (52)
    rng = np.random.default_rng(5)
    mixed = rng.normal(size=(n, 8)).astype(np.float32)
    mixed[57:171] = 0.0  # chunks 1 and 2 zero: runs [0, 1) and [3, 6) written
    mixed[-3:] = 0.0  # the short chunk partly zero: written
    signed = np.zeros((n, 8), np.float32)
    signed[200, 3] = -0.0  # a negative zero in chunk 3 only
    nan_tail = np.zeros((n, 8), np.float32)
    nan_tail[-1, 0] = np.nan  # in the short last chunk only
    ep = {"time": Channel(np.arange(n) / 100.0, "s", ("time",)),
          "shear": Channel(np.zeros((n, 8, 2), np.float32), "Pa", ("time", "taxel", "xy")),
          "mixed": Channel(mixed, "Pa", ("time", "taxel")),
          "signed": Channel(signed, "Pa", ("time", "taxel")),
          "nan_tail": Channel(nan_tail, "Pa", ("time", "taxel")),
          "adc": Channel(np.zeros((n, 3), np.int16), "counts", ("time", "channel"))}
    if not fast:
        ep["empty"] = Channel(np.zeros((0,), np.float32), "1", ("time",))
    kw = dict(source="sim", config_json=CONFIG, root_seed=1, shard_index=0, sensor_attrs={"family": "velostat"},
              compression=compression)
    skipped = write_recording(tmp_path / "skip.h5", {"ep-0": ep}, **kw)
    monkeypatch.setattr(rc, "SKIP_ZERO_CHUNKS", False)
    whole = write_recording(tmp_path / "whole.h5", {"ep-0": ep}, **kw)
    with Recording(skipped) as a, Recording(whole) as b:
        for name, ch in ep.items():
            assert a.read("ep-0", name).tobytes() == b.read("ep-0", name).tobytes() == ch.data.tobytes(), name
        assert np.signbit(a.read("ep-0", "signed")[200, 3]) and np.isnan(a.read("ep-0", "nan_tail")[-1, 0])
        assert a.compute_content_sha256() == a.content_sha256 == b.content_sha256
        sa, sb = a.summary(from_data=False), b.summary(from_data=False)
        assert sa["channels"] == sb["channels"] == a.summary()["channels"] and sa["n_samples"] == sb["n_samples"]
        d = a._f["episodes/ep-0"]
        assert d["shear"].id.get_storage_size() == 0 and d["adc"].id.get_storage_size() == 0
        assert d["mixed"].chunks == (57, 8)
        stored = {name: d[name].id.get_num_chunks() for name in ("mixed", "signed", "nan_tail", "time")}
        assert stored == {"mixed": 4, "signed": 1, "nan_tail": 1, "time": 2}  # time: two chunks, both nonzero
        assert b._f["episodes/ep-0/mixed"].id.get_num_chunks() == 6
    assert skipped.stat().st_size < whole.stat().st_size


def test_nonzero_chunks_reads_every_byte():
    """The per-chunk test sees one nonzero byte anywhere: in whole chunks (any word size), in the short last ones
    along time and along the taxel axis."""
    cases = [((10, 3), (4, 3), np.float32), ((9, 5), (3, 5), np.int16), ((7, 1), (2, 1), np.uint8),
             ((5, 2, 2), (5, 2, 2), np.float64), ((7,), (3,), np.float32), ((6, 7, 2), (4, 3, 2), np.float32)]
    for shape, chunks, dtype in cases:
        a = np.zeros(shape, dtype)
        assert not rc._nonzero_chunks(a, chunks).any()
        idx = np.indices(shape).reshape(len(shape), -1).T
        for i in idx:
            for byte in range(a.itemsize):
                a[...] = 0
                a.view(np.uint8).reshape(*shape, a.itemsize)[tuple(i) + (byte,)] = 1
                want = np.zeros((-(-shape[0] // chunks[0]), -(-shape[1] // chunks[1]) if len(shape) > 1 else 1), bool)
                want[i[0] // chunks[0], i[1] // chunks[1] if len(shape) > 1 else 0] = True
                assert (rc._nonzero_chunks(a, chunks) == want).all(), (shape, tuple(i), byte)


def test_taxel_fields_are_chunked_in_blocks_and_untouched_blocks_not_stored(tmp_path, monkeypatch):
    """A taxel field is chunked in blocks of TAXEL_BLOCK taxels along its taxel axis (the last block short): a press
    on a few taxels leaves the other blocks unwritten; the data read back (whole and by slices) are the same bytes
    and the content hash is that of the whole-frame layout (TAXEL_BLOCK = 0). A short episode, whose blocks would be
    chunks under TAXEL_BLOCK_MIN_BYTES, keeps whole frames."""
    n, N = 1200, 40  # blocks of 16, 16, 8 taxels: 77 kB chunks of pressure
    rng = np.random.default_rng(9)
    pressure = np.zeros((n, N), np.float32)
    pressure[100:300, 18:22] = rng.uniform(1e3, 5e4, (200, 4)).astype(np.float32)  # the middle block only
    pressure[450:470, 20] = 1e3  # (inside the first 500 frames too)
    shear = np.zeros((n, N, 2), np.float32)
    shear[100:300, 18:22] = rng.normal(0, 1e-3, (200, 4, 2)).astype(np.float32)
    ep = {"time": Channel(np.arange(n) / 100.0, "s", ("time",)),
          "pressure": Channel(pressure, "Pa", ("time", "taxel")),
          "shear": Channel(shear, "Pa", ("time", "taxel", "xy")),
          "position": Channel(rng.normal(size=(n, 3)), "m", ("time", "xyz"))}
    kw = dict(source="sim", config_json=CONFIG, root_seed=1, shard_index=0, sensor_attrs={"family": "velostat"},
              compression="lz4")
    blocked = write_recording(tmp_path / "blocked.h5", {"ep-0": ep}, **kw)
    monkeypatch.setattr(rc, "TAXEL_BLOCK", 0)
    monkeypatch.setattr(rc, "_TEMPLATES", type(rc._TEMPLATES)())  # no template of the blocked layout
    frames = write_recording(tmp_path / "frames.h5", {"ep-0": ep}, **kw)
    with Recording(blocked) as a, Recording(frames) as b:
        d = a._f["episodes/ep-0"]
        assert d["pressure"].chunks == (n, 16) and d["shear"].chunks == (n, 16, 2)
        assert d["position"].chunks == (n, 3) and b._f["episodes/ep-0/pressure"].chunks == (n, N)
        assert d["pressure"].id.get_num_chunks() == 1 and d["shear"].id.get_num_chunks() == 1
        for name, ch in ep.items():
            assert a.read("ep-0", name).tobytes() == b.read("ep-0", name).tobytes() == ch.data.tobytes(), name
        np.testing.assert_array_equal(a.read("ep-0", "pressure", slice(250, 260)), pressure[250:260])
        assert a.compute_content_sha256() == a.content_sha256 == b.content_sha256
    assert blocked.stat().st_size < frames.stat().st_size
    short = rc.Channel(pressure[:500], "Pa", ("time", "taxel"))  # 500 x 16 x 4 B = 32 kB a block: whole frames
    monkeypatch.setattr(rc, "TAXEL_BLOCK", 16)
    assert rc._chunk_shape(short) == (500, N) and rc._chunk_shape(ep["pressure"]) == (n, 16)


@pytest.mark.parametrize("case", range(40))
def test_zero_chunk_writes_read_back_for_any_layout(tmp_path, case):
    """Random shapes (1-4 axes, a taxel axis or not), chunk sizes (partial chunks along time and taxels), dtypes and
    zero patterns (whole chunks, rows, single values, -0.0): the dataset `_write_rows` fills reads back as the array,
    bit for bit, and stores no chunk that is all zero. Deterministic (seeded per case)."""
    rng = np.random.default_rng([18, case])
    ndim = int(rng.integers(1, 5))
    shape = tuple(int(rng.integers(1, 40)) for _ in range(ndim))
    chunks = tuple(int(rng.integers(1, n + 1)) if k < 2 else n for k, n in enumerate(shape))
    dtype = [np.float32, np.float64, np.int16, np.uint8][case % 4]
    a = (rng.normal(size=shape) * 100).astype(dtype)
    mask = rng.random(shape) < [0.0, 0.5, 0.9, 1.0][(case // 4) % 4]  # share of zeros, crossed with the dtypes
    a[mask] = 0
    if shape[0] > 2:
        a[rng.integers(shape[0])] = 0  # a zero frame
    if dtype in (np.float32, np.float64) and a.size:
        a.reshape(-1)[rng.integers(a.size)] = -0.0
    with h5py.File(tmp_path / "x.h5", "w") as f:
        ds = f.create_dataset("x", shape=shape, dtype=dtype, chunks=chunks, fletcher32=True, compression="lzf")
        rc._write_rows(ds.id, a, chunks)
        assert ds[...].tobytes() == a.tobytes()
        nz = rc._nonzero_chunks(a, chunks)
        assert ds.id.get_num_chunks() == int(nz.sum())


@pytest.mark.parametrize("n", [1200, 30000])  # one chunk along time per taxel block, and several (1 MiB cap)
def test_nonzero_block_hint_gives_the_scanned_file(tmp_path, monkeypatch, n):
    """A field whose producer flags its all-zero taxel blocks (`Channel.nonzero_blocks`, the GPU feed's BlockSparse)
    is written without scanning them: the same chunks stored, the same bytes read back, the same content hash and
    stored summary as the scanned write. A block flagged non-zero is still scanned along time where it holds several
    chunks, so its zero stretches stay unwritten; a hint of the wrong length is a clear error."""
    from simulate.contact.field_blocks import blocks_of

    N = 40  # blocks of 16, 16, 8 taxels
    rng = np.random.default_rng(3)
    pressure = np.zeros((n, N), np.float32)
    pressure[100:300, 18:22] = rng.uniform(1e3, 5e4, (200, 4)).astype(np.float32)  # the middle block only
    pressure[150, 17] = -0.0  # a signed zero inside a loaded block stays as written
    shear = np.zeros((n, N, 2), np.float32)
    shear[100:300, 33:35] = rng.normal(0, 1e-3, (200, 2, 2)).astype(np.float32)  # the last, short block only
    hints = {name: blocks_of(a[None], rc.TAXEL_BLOCK).nonzero_blocks(0) for name, a in (("pressure", pressure), ("shear", shear))}
    assert hints["pressure"][1].tolist() == [False, True, False] and hints["shear"][1].tolist() == [False, False, True]

    def episode(hinted):
        return {"time": Channel(np.arange(n) / 100.0, "s", ("time",)),
                **{name: Channel(a, "Pa", dims, nonzero_blocks=hints[name] if hinted else None)
                   for name, a, dims in (("pressure", pressure, ("time", "taxel")), ("shear", shear, ("time", "taxel", "xy")))}}

    kw = dict(source="sim", config_json=CONFIG, root_seed=1, shard_index=0, sensor_attrs={"family": "velostat"},
              compression="lz4")
    scans, scan = [], rc._nonzero_chunks
    monkeypatch.setattr(rc, "_nonzero_chunks", lambda data, chunks: scans.append(data.shape) or scan(data, chunks))
    hinted = write_recording(tmp_path / "hinted.h5", {"ep-0": episode(True)}, **kw)
    # what was scanned: the flagged block's column where it holds several chunks along time, nothing else
    assert scans == ([] if n == 1200 else [(n, 16), (n, 8, 2)])
    scanned = write_recording(tmp_path / "scanned.h5", {"ep-0": episode(False)}, **kw)
    assert [s[1:] for s in scans[2 if n > 1200 else 0:]] == [(N,), (N, 2)]
    with Recording(hinted) as a, Recording(scanned) as b:
        for name in ("pressure", "shear"):
            da, db = a._f[f"episodes/ep-0/{name}"], b._f[f"episodes/ep-0/{name}"]
            assert da.id.get_num_chunks() == db.id.get_num_chunks() == 1, name  # n = 30000: one of two along time
            assert a.read("ep-0", name).tobytes() == b.read("ep-0", name).tobytes() == episode(False)[name].data.tobytes()
        assert np.signbit(a.read("ep-0", "pressure")[150, 17])
        assert a.content_sha256 == b.content_sha256 == a.compute_content_sha256()
        sa, sb = a.summary(from_data=False), b.summary(from_data=False)
        assert sa["channels"] == sb["channels"] == a.summary()["channels"] and sa["n_samples"] == sb["n_samples"]
        assert sa["channels"]["pressure"]["min"] == 0.0 and sa["channels"]["shear"]["min"] < 0.0
    with pytest.raises(ValueError, match="nonzero_blocks"):
        Channel(pressure, "Pa", ("time", "taxel"), nonzero_blocks=(16, np.ones(2, bool)))

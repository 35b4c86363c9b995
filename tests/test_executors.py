"""Distributed generation (simulate/generation/executors.py): a local process pool and Ray give the serial dataset,
a killed worker's shard is retried, exhausted retries give a clear error and a rerun resumes."""

import importlib.util
import os
from pathlib import Path

import numpy as np
import pytest

from scenes import load_scene
from sensors.data.manifest import read_manifest, shard_path
from sensors.data.recording import Recording
from simulate.generation import executors, run

FAST = ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=6", "pad.taxels_y=6",
        "generation.episodes=4", "generation.episodes_per_shard=1", "generation.root_seed=11"]


@pytest.fixture(scope="module")
def cfg():
    return load_scene("cnt_pdms", FAST)


@pytest.fixture(scope="module")
def serial(cfg, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    run.generate(cfg, out)
    return out


def _episodes(directory, n_shards):
    eps = {}
    for i in range(n_shards):
        with Recording(shard_path(directory, i)) as rec:
            for ep in rec.episode_ids:
                eps[ep] = {ch: rec.read(ep, ch) for ch in rec.channels(ep)}
    return eps


def _assert_same_dataset(a, b, n_shards, n_episodes=4):
    ea, eb = _episodes(a, n_shards), _episodes(b, n_shards)
    assert list(ea) == list(eb) and len(ea) == n_episodes
    for ep in ea:
        assert list(ea[ep]) == list(eb[ep])
        for ch in ea[ep]:
            assert ea[ep][ch].dtype == eb[ep][ch].dtype
            assert ea[ep][ch].tobytes() == eb[ep][ch].tobytes(), (ep, ch)
    ma, mb = read_manifest(a), read_manifest(b)
    for key in ("config_sha256", "total_episodes", "splits"):
        assert ma[key] == mb[key]
    assert [s["episode_seeds"] for s in ma["shards"]] == [s["episode_seeds"] for s in mb["shards"]]


def _inject(monkeypatch, tmp_path, shard, mode):
    marker = tmp_path / f"fault-{shard}"
    monkeypatch.setenv("PIEZOTWIN_FAULT_SHARD", str(shard))
    monkeypatch.setenv("PIEZOTWIN_FAULT_MARKER", str(marker))
    monkeypatch.setenv("PIEZOTWIN_FAULT_MODE", mode)
    return marker


def test_local_pool_equals_serial_and_retries_a_killed_worker(cfg, serial, tmp_path, monkeypatch):
    marker = _inject(monkeypatch, tmp_path, 2, "exit")  # the worker running shard 2 dies once
    seen = []
    out = tmp_path / "pool"
    executors.generate(cfg, out, executor="local", workers=2, on_shard=lambda s, n, skip: seen.append((s, n, skip)))
    assert marker.is_file()  # the fault did happen
    assert sorted(seen) == [(s, 1, False) for s in range(4)]  # progress: each shard once, as it finished
    assert not list(out.glob("*.tmp"))
    _assert_same_dataset(serial, out, 4)


def test_a_pool_that_breaks_between_two_results_loses_no_shard(cfg, serial, tmp_path, monkeypatch):
    """A worker can die after one shard's result and before the next submit: the broken pool then refuses the
    submit itself (BrokenProcessPool from `submit`, seen on a loaded 2-core machine). That shard never ran: it is
    not charged an attempt (max_retries=0 still finishes) and runs in the next pool; every shard is written once."""
    import concurrent.futures as cf
    from concurrent.futures.process import BrokenProcessPool

    pools = []

    class InlinePool:  # runs each task at submit; the first pool breaks at its second submit
        def __init__(self, max_workers, mp_context=None, **kw):
            self.n = 0
            pools.append(self)

        def submit(self, fn, *args, **kwargs):
            self.n += 1
            if len(pools) == 1 and self.n == 2:
                raise BrokenProcessPool("A child process terminated abruptly")
            f = cf.Future()
            f.set_result(fn(*args, **kwargs))
            return f

        def shutdown(self, wait=True, cancel_futures=False):
            pass

    monkeypatch.setattr(cf, "ProcessPoolExecutor", InlinePool)
    seen = []
    out = tmp_path / "pool"
    executors.generate(cfg, out, executor="local", workers=2, max_retries=0,
                       on_shard=lambda s, n, skip: seen.append((s, n, skip)))
    assert len(pools) == 2 and sorted(seen) == [(s, 1, False) for s in range(4)]
    _assert_same_dataset(serial, out, 4)


@pytest.mark.slow  # two more pool start-ups (~11 s on 2 cores)
def test_exhausted_retries_fail_clearly_then_resume(cfg, serial, tmp_path, monkeypatch):
    marker = _inject(monkeypatch, tmp_path, 1, "raise")
    out = tmp_path / "pool"
    with pytest.raises(executors.ShardFailedError, match=r"shard 1: failed 1 time.*injected fault"):
        executors.generate(cfg, out, workers=2, max_retries=0)
    assert marker.is_file() and not (out / "manifest.json").exists()
    assert not shard_path(out, 1).exists()
    done_before = {i: shard_path(out, i).stat().st_mtime_ns for i in (0, 2, 3) if shard_path(out, i).exists()}
    seen = []
    executors.generate(cfg, out, workers=2, on_shard=lambda s, n, skip: seen.append((s, skip)))
    assert (1, False) in seen and all((i, True) in seen for i in done_before)  # kept shards are skipped
    assert {i: shard_path(out, i).stat().st_mtime_ns for i in done_before} == done_before
    _assert_same_dataset(serial, out, 4)


def test_arguments_are_checked(cfg, tmp_path):
    with pytest.raises(ValueError, match="executor must be one of"):
        executors.generate(cfg, tmp_path, executor="dask")
    with pytest.raises(ValueError, match="workers must be >= 1"):
        executors.generate(cfg, tmp_path, workers=0)


@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="ray not installed (optional extra)")
def test_ray_local_cluster_equals_serial_and_retries(cfg, serial, tmp_path, monkeypatch):
    marker = _inject(monkeypatch, tmp_path, 3, "exit")  # a Ray worker dies once; Ray's max_retries reruns it
    out = tmp_path / "ray"
    seen = []
    executors.generate(cfg, out, executor="ray", workers=2, on_shard=lambda s, n, skip: seen.append(s))
    assert marker.is_file()
    assert sorted(seen) == [0, 1, 2, 3]
    _assert_same_dataset(serial, out, 4)


def test_episode_channels_do_not_depend_on_shard_size_or_batching(serial, tmp_path):
    """5 episodes in one shard (simulated in batches of 4 + 1, written while the next batch runs) equal
    the same episodes made one per shard."""
    cfg5 = load_scene("cnt_pdms", FAST[:-3] + ["generation.episodes=5", "generation.episodes_per_shard=5",
                                               "generation.root_seed=11"])
    assert run.shard_batches(5) == [slice(0, 4), slice(4, 5)]
    run.generate(cfg5, tmp_path / "one")
    one = _episodes(tmp_path / "one", 1)
    ref = _episodes(serial, 4)
    assert list(one) == [f"ep-{k:06d}" for k in range(5)]
    for ep in ref:
        for ch in ref[ep]:
            assert one[ep][ch].tobytes() == ref[ep][ch].tobytes(), (ep, ch)


def test_gpu_feed_equals_serial_and_retries_a_killed_writer(tmp_path, monkeypatch):
    """The GPU feed (simulate.generation.feed: episodes of several shards as one batch here, shards written by writer
    processes), forced on the CPU engine: mixed episode lengths, batches of 2 shards, a writer dies once ->
    the same files as the serial loop, and no shared block left behind."""
    from simulate.generation import feed

    mixed = load_scene("cnt_pdms", ["protocol.frequencies_hz=[2.0,4.0]", "protocol.cycles=1", "pad.taxels_x=3",
                                    "pad.taxels_y=2", "generation.episodes=7", "generation.episodes_per_shard=2",
                                    "generation.root_seed=5"])
    ref = tmp_path / "serial"
    run.generate(mixed, ref)
    monkeypatch.setattr(feed, "FEED_WORLDS", 8)  # a ramp of >= 2, >= 4 episodes, then >= 8: three batches
    assert feed._groups(mixed, [0, 1, 2, 3], 8) == [[0], [1, 2], [3]]
    monkeypatch.setattr(feed, "RAMP_BATCHES", 0)
    assert feed._groups(mixed, [0, 1, 2, 3], 3) == [[0, 1], [2, 3]]  # no ramp: >= 3 episodes each
    monkeypatch.setattr(feed, "RAMP_BATCHES", 2)
    packs = feed.produce(mixed, [0, 1], run.make_sensor(mixed, "warp", "cpu"))
    assert max(len(pk.pieces) for pk in packs) == 2  # a shard with both episode lengths: one piece per length
    marker = _inject(monkeypatch, tmp_path, 1, "exit")
    seen = []
    out = tmp_path / "feed"
    # the blocks this run's driver made or attached (the physics processes' too: the driver attaches each to
    # read and unlink it); only these are checked, so another test's blocks (a parallel worker) do not count
    from multiprocessing import shared_memory

    touched = []
    real_init = shared_memory.SharedMemory.__init__

    def tracking_init(self, *a, **k):
        real_init(self, *a, **k)
        touched.append(self._name.lstrip("/"))

    monkeypatch.setattr(shared_memory.SharedMemory, "__init__", tracking_init)
    executors.generate(mixed, out, workers=2, feed=True, on_shard=lambda s, n, skip: seen.append((s, n)))
    assert marker.is_file() and sorted(seen) == [(0, 2), (1, 2), (2, 2), (3, 1)]
    assert touched and not [n for n in touched if (Path("/dev/shm") / n).exists()]  # every shared block was unlinked
    a, b = _episodes(ref, 4), _episodes(out, 4)
    assert list(a) == list(b) and len(a) == 7
    for ep in a:
        assert list(a[ep]) == list(b[ep])
        for ch in a[ep]:
            assert a[ep][ch].dtype == b[ep][ch].dtype and a[ep][ch].tobytes() == b[ep][ch].tobytes(), (ep, ch)
    for i in range(4):
        with Recording(shard_path(ref, i)) as ra, Recording(shard_path(out, i)) as rb:
            for ep in ra.episode_ids:
                np.testing.assert_equal(rb.episode_attrs(ep), ra.episode_attrs(ep))
            assert ra.sensor_attrs.keys() == rb.sensor_attrs.keys()
            # the feed's writers store the summary that reading the data gives, as the serial loop's writer does
            stored, read = rb.summary(from_data=False), rb.summary()
            assert rb.has_stored_summary and stored == read
            assert {k: v for k, v in stored.items() if k not in ("path", "created_utc")} == \
                {k: v for k, v in ra.summary(from_data=False).items() if k not in ("path", "created_utc")}
    # the manifest entries the writers made equal what the driver reads back from the files
    from sensors.data.manifest import describe_shard, verify_manifest

    ma, mb = read_manifest(ref), read_manifest(out)
    assert [s["episode_seeds"] for s in mb["shards"]] == [s["episode_seeds"] for s in ma["shards"]]
    assert ma["splits"] == mb["splits"] and verify_manifest(out) == []
    described = [describe_shard(shard_path(out, i)) for i in range(4)]
    assert mb["shards"] == [{k: v for k, v in d.items() if k != "summary"} for d in described]
    # the dataset's summary: the writers' merged in the feed's driver, the files' in the serial loop's, the same
    assert mb["summary"] == ma["summary"] and mb["summary"]["n_samples"] == sum(d["summary"]["n_samples"] for d in described)


def test_feed_steps_a_contact_stage_in_full_batches_and_writes_what_the_serial_loop_writes(tmp_path, monkeypatch):
    """ntype's press_stroke has its own contact stage: its worlds step in the feed's physics processes (their
    `press_stroke_physics` handed to the driver, which makes the load field and runs the sensor chain), its
    latency-bound batches cost about the same whatever their size, so the feed makes them full from the first (no ramp
    of worlds / 4, worlds / 2), and the files are those of the serial loop."""
    from simulate.generation import feed

    ntype = load_scene("ntype", ["generation.episodes=6", "generation.episodes_per_shard=1", "generation.root_seed=3"])
    ref = tmp_path / "serial"
    run.generate(ntype, ref)
    monkeypatch.setattr(feed, "FEED_WORLDS", 12)  # worlds // 4 = 3 episodes a batch
    made = []
    real = feed._groups

    def spy(*a, **k):
        made.append(real(*a, **k))
        return made[-1]

    monkeypatch.setattr(feed, "_groups", spy)
    from multiprocessing import shared_memory

    touched, real_init = [], shared_memory.SharedMemory.__init__  # the blocks the driver made or attached

    def tracking_init(self, *a, **k):
        real_init(self, *a, **k)
        touched.append(self._name.lstrip("/"))

    monkeypatch.setattr(shared_memory.SharedMemory, "__init__", tracking_init)
    out = tmp_path / "feed"
    executors.generate(ntype, out, workers=2, feed=True)
    assert made == [[[0, 1, 2], [3, 4, 5]]]
    assert feed.LAST_RUN_SECONDS.get("physics: worlds", 0) > 0  # the second batch stepped in a physics process
    assert touched and not [n for n in touched if (Path("/dev/shm") / n).exists()]  # its physics blocks unlinked
    assert real(ntype, list(range(6)), 3) == [[0], [1, 2, 3], [4, 5]]  # what the ramp would have made
    _assert_same_dataset(ref, out, 6, 6)


def test_gpu_feed_resubmits_when_the_writer_pool_refuses_a_shard(cfg, serial, tmp_path, monkeypatch):
    """A writer that dies between two collects breaks the pool before the next shard is handed over: the feed's
    submit then settles the pool's writes, starts a new pool and hands the shard over again -> the same files
    (the race behind a once-in-a-while BrokenProcessPool from `pool.submit`)."""
    import concurrent.futures
    from concurrent.futures.process import BrokenProcessPool

    refused = []

    class RefusingOnce(concurrent.futures.ProcessPoolExecutor):
        def submit(self, fn, *args, **kwargs):
            if not refused and args and getattr(args[2], "shard", None) == 2:
                refused.append(self)
                raise BrokenProcessPool("a writer died (simulated)")
            return super().submit(fn, *args, **kwargs)

    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", RefusingOnce)  # feed imports it when it runs
    out = tmp_path / "feed"
    executors.generate(cfg, out, workers=2, feed=True)
    assert len(refused) == 1
    _assert_same_dataset(serial, out, 4)


@pytest.mark.gpu
def test_feed_packs_each_gpu_slice_before_the_next_overwrites_its_staging(gpu_device, monkeypatch):
    """The feed's producer on CUDA: outputs copied back into reused page-locked buffers (one per call site),
    packed into shared blocks of a BlockPool slice by slice (3-episode slices, 2-episode shards), equal to the
    same physics run through the plain path (a fresh host array per copy)."""
    from sensors.data.manifest import episode_seed
    from simulate.contact import (
        load_field as contact,  # where iter_load_batches looks simulate_sensors up
    )
    from simulate.contact.load_field import physics_engine
    from simulate.generation import feed

    dev = "cpu" if gpu_device == "cpu" else "cuda"
    cfg = load_scene("cnt_pdms", FAST[:-3] + ["sensor.readout=taxel", "generation.physics=mujoco_warp", f"generation.device={dev}",
                                              "generation.record=[time,position,force_taxel,adc]", "generation.episodes=7",
                                              "generation.episodes_per_shard=2", "generation.root_seed=3"])
    sensor = run.make_sensor(cfg, "warp", physics_engine(cfg)[1])
    physics, real = [], contact.simulate_sensors  # one physics run for both (GPU atomics need not repeat bit for bit)
    monkeypatch.setattr(contact, "simulate_sensors", lambda *a: physics[0] if physics else physics.append(real(*a)) or physics[0])
    monkeypatch.setattr(run, "SENSOR_SLICE", 3)
    pool = feed.BlockPool()
    try:
        packs = feed.produce(cfg, [0, 1, 2, 3], sensor, pool=pool)
        assert len(pool.blocks) >= 4  # the pieces went into shared blocks
        seeds = [episode_seed(cfg.generation.root_seed, k) for k in range(7)]
        ref = run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in range(7)], sensor, indices=list(range(7)))
        got = {}
        for p in packs:
            pieces = p.arrays({n: pool.blocks[n].buf for n in p.block_names})
            for ep_id, _, piece, row in p.episodes:
                got[ep_id] = {n: pieces[piece][n][row] if spec[3] else pieces[piece][n] for n, spec in p.specs.items()}
            pieces = None
        assert max(float(np.abs(r.channels["force_taxel"].data).max()) for r in ref) > 0.1  # they press
        for r in ref:
            for n, c in r.channels.items():
                np.testing.assert_array_equal(got[r.ep_id][n], c.data, err_msg=f"{r.ep_id} {n}")
        got = None
    finally:
        pool.close()


def test_gpu_feed_bounded_by_host_memory_still_finishes(cfg, serial, tmp_path, monkeypatch):
    """With a pending-bytes budget smaller than one shard, the feed writes one shard at a time (no deadlock)
    and the dataset is the serial one."""
    from simulate.generation import feed

    monkeypatch.setattr(feed, "PENDING_RAM_FRACTION", 1e-12)
    monkeypatch.setattr(feed, "FEED_WORLDS", 2)
    out = tmp_path / "bounded"
    executors.generate(cfg, out, workers=2, feed=True)
    _assert_same_dataset(serial, out, 4)


def _gpu_slicing_on_cpu(monkeypatch):
    """A 7-episode cnt_pdms scene (2-episode shards) whose sensor stage is sliced as on MuJoCo Warp, over C MuJoCo's
    physics run once (the engine name patched; the load field on the host): (cfg, sensor)."""
    from simulate.contact import load_field as contact

    cfg = load_scene("cnt_pdms", FAST[:-3] + ["sensor.readout=taxel", "generation.record=[time,position,force_taxel,adc]",
                                              "generation.episodes=7", "generation.episodes_per_shard=2", "generation.root_seed=3"])
    sensor = run.make_sensor(cfg, "warp", "cpu")
    monkeypatch.setattr(run, "physics_engine", lambda cfg: ("mujoco_warp", "elsewhere"))  # GPU slicing, host load field
    physics, real = [], contact.simulate_sensors  # one physics run for both paths
    monkeypatch.setattr(contact, "simulate_sensors", lambda *a: physics[0] if physics else physics.append(real(*a)) or physics[0])
    return cfg, sensor


def test_feed_hands_each_shard_on_as_its_last_slice_is_packed(monkeypatch):
    """A modest batch as on MuJoCo Warp (the slicing of the GPU path, here over C MuJoCo's physics: the engine
    name is patched): its one length group goes in SLICES_PER_LENGTH slices, and `iter_produce` yields each
    shard right after the slice that completes it (the writers start while the batch's later slices run),
    with the channels the plain path makes."""
    from sensors.data.manifest import episode_seed
    from simulate.generation import feed

    cfg, sensor = _gpu_slicing_on_cpu(monkeypatch)
    events, plain = [], run.simulate_slices

    def slices(*a, **k):
        for part, protos, arrays in plain(*a, **k):
            events.append(len(part))
            yield part, protos, arrays

    monkeypatch.setattr(run, "simulate_slices", slices)
    runs = {}
    for overlap in (False, True):  # packed one after the other, or slice i packed while slice i + 1 runs
        monkeypatch.setattr(feed, "PACK_OVERLAP", overlap)
        events.clear()
        got = runs[overlap] = {}
        for p in feed.iter_produce(cfg, [0, 1, 2, 3], sensor):
            events.append(f"shard {p.shard}")
            for ep_id, _, piece, row in p.episodes:
                got[ep_id] = {n: p.pieces[piece][n][row] if spec[3] else p.pieces[piece][n] for n, spec in p.specs.items()}
        assert feed.SLICES_PER_LENGTH == 4
        assert events == ([2, 2, "shard 0", 2, "shard 1", 1, "shard 2", "shard 3"] if overlap  # one slice later
                          else [2, "shard 0", 2, "shard 1", 2, "shard 2", 1, "shard 3"])
    monkeypatch.setattr(run, "simulate_slices", plain)
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in range(7)]
    ref = run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in range(7)], sensor, indices=list(range(7)))
    assert max(float(np.abs(r.channels["force_taxel"].data).max()) for r in ref) > 0.1  # they press
    for got in runs.values():
        for r in ref:
            for n, c in r.channels.items():
                np.testing.assert_array_equal(got[r.ep_id][n], c.data, err_msg=f"{r.ep_id} {n}")


def test_staging_plan_names_the_largest_slice_copies(monkeypatch):
    """While the first batch steps, the GPU feed page-locks the staging buffers that the batch's slices will copy
    back into (`probe_batch`'s plan, from one episode on zero sensordata): the plan names every call site the
    slices copy from, with the bytes of the largest slice (one episode length here: exactly), and a larger
    batch scales it by its slice size."""
    from sensors import warp_setup as ws
    from sensors.data.manifest import episode_seed
    from simulate.generation import feed

    cfg, sensor = _gpu_slicing_on_cpu(monkeypatch)
    monkeypatch.setattr(feed, "SLICES_PER_LENGTH", 2)  # 7 episodes: slices of 4 and 3
    gids = list(range(7))
    _, plan = feed.probe_batch(cfg, sensor, gids)
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in gids]
    with ws.host_staging(), ws.staging_log() as log:
        for _ in run.simulate_slices(cfg, seeds, sensor, 1, gids, None, None, feed.SLICES_PER_LENGTH):
            pass
    assert log and plan == log
    assert len({k[0] for k in log}) >= 2  # several call sites (the sensor's outputs)
    _, plan_big = feed.probe_batch(cfg, sensor, list(range(70)))  # slices of 35 episodes
    assert plan_big == {k: v * 35 // 4 for k, v in plan.items()}
    monkeypatch.setattr(feed, "PACK_OVERLAP", True)  # the pack alternates two sets of buffers: both planned
    _, plan_two = feed.probe_batch(cfg, sensor, gids)
    assert plan_two == {**plan, **{(site, 1): v for (site, _), v in plan.items()}}


def _assert_packs_are_plain(cfg, sensor, pool, packs, n_episodes: int) -> None:
    """Every channel of every packed episode (read from the pool's blocks) equals the plain path's."""
    from sensors.data.manifest import episode_seed

    seeds = [episode_seed(cfg.generation.root_seed, k) for k in range(n_episodes)]
    ref = run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in range(n_episodes)], sensor,
                                indices=list(range(n_episodes)))
    for p in packs:
        pieces = p.arrays({n: pool.blocks[n].buf for n in p.block_names})
        for ep_id, _, piece, row in p.episodes:
            r = next(r for r in ref if r.ep_id == ep_id)
            for n, c in r.channels.items():
                got = pieces[piece][n][row] if p.specs[n][3] else pieces[piece][n]
                np.testing.assert_array_equal(got, c.data, err_msg=f"{ep_id} {n}")
        pieces = None


@pytest.mark.parametrize("split", [False, True])
def test_pack_into_blocks_populated_ahead_from_the_estimate(monkeypatch, split):
    """While a batch's physics steps, the feed populates shared blocks (arenas) for its pack from an estimate made
    on zero sensordata (`batch_pack_bytes`): the estimate equals the bytes packed (one episode length), the pieces
    are carved from the arenas at aligned offsets (several per arena), the channels are the plain path's (each
    piece copied in the driver's thread, or split over the pack threads: split), and an arena is carved from its
    start again once every piece has come back."""
    from simulate.generation import feed

    cfg, sensor = _gpu_slicing_on_cpu(monkeypatch)
    monkeypatch.setattr(feed, "PACK_SPLIT_BYTES", 0 if split else 1 << 62)
    monkeypatch.setattr(feed, "PACK_THREADS", 3)  # more threads than some pieces have rows: empty shares too
    need = feed.batch_pack_bytes(cfg, sensor, list(range(7)))
    monkeypatch.setattr(feed, "ARENA_BYTES", 3 * need // 7 + 4096)  # three episodes' pieces at most per arena
    pool = feed.BlockPool()
    try:
        pool.populate_ahead(3 * feed.ARENA_BYTES)
        pool._filler.join()
        arenas = list(pool.arenas)
        assert len(arenas) == 3 and pool.stop_populating(wait=True) >= need
        packs = feed.produce(cfg, [0, 1, 2, 3], sensor, pool=pool)
        in_blocks = sum(int(np.prod(shape)) * np.dtype(dt).itemsize for p in packs for b in p.blocks for _, dt, shape in b[1].values())
        assert in_blocks == need  # (the time axis, shared by a piece's episodes, stays in process memory)
        assert set(pool.blocks) == set(arenas)  # every piece went into an arena, no block of its own
        offsets = [off for p in packs for b in p.blocks for off, _, _ in b[1].values()]
        assert all(o % feed.ARENA_ALIGN == 0 for o in offsets) and any(o > 0 for o in offsets)
        assert [pool.arenas[a][1] for a in arenas] == [2, 1, 1]  # pieces lent per arena (2 + 2 + 2 + 1 episodes)
        _assert_packs_are_plain(cfg, sensor, pool, packs, 7)
        for p in packs:  # the shards are written: their pieces come back
            for name in p.block_names:
                pool.put(name)
        assert all(pool.arenas[a] == [0, 0] for a in arenas)
        assert pool.get(need // 7)[0].name == arenas[0]
    finally:
        pool.close()
    assert not pool.blocks and not pool.arenas


def test_pool_packs_while_arenas_are_populated(monkeypatch):
    """POPULATE_THROUGH: the driver packs while the populating thread is still adding arenas. Every piece lands
    whole in one block (an arena populated by then or a block of its own), with the plain path's bytes, and the
    thread goes on to its full size meanwhile (`populated_bytes` does not stop it)."""
    from simulate.generation import feed

    cfg, sensor = _gpu_slicing_on_cpu(monkeypatch)
    need = feed.batch_pack_bytes(cfg, sensor, list(range(7)))
    monkeypatch.setattr(feed, "ARENA_BYTES", need // 7 + 4096)
    pool = feed.BlockPool()
    try:
        pool.populate_ahead(7 * feed.ARENA_BYTES)
        early = pool.populated_bytes()
        packs = feed.produce(cfg, [0, 1, 2, 3], sensor, pool=pool)
        pool._filler.join()
        assert early <= pool.populated_bytes() == 7 * feed.ARENA_BYTES
        assert all(n in pool.blocks for p in packs for n in p.block_names)
        _assert_packs_are_plain(cfg, sensor, pool, packs, 7)
    finally:
        pool.close()
    assert not pool.blocks and not pool.arenas


# fabric_1's staircase, shortened (the same kind, controls and sensor; two levels, 1 s dwells)
FABRIC_SHORT = ["protocol.stair_return_points_n=[1.0, 2.0]", "protocol.stair_dwell_s=1 s", "generation.episodes=3",
                "generation.episodes_per_shard=2", "generation.root_seed=7"]


def test_feed_on_fabric_writes_the_serial_files(tmp_path):
    """The whole feed on fabric_1 (its physics process, the driver's load field and sensor chain, the writers; the
    first batch no longer streamed: session 10's H100 A/B measured it neutral, 113.7 s against 113.3 s without)
    against the serial loop: the same bytes in every channel."""
    from simulate.generation import feed

    cfg = load_scene("fabric_1", FABRIC_SHORT)
    ref, out = tmp_path / "serial", tmp_path / "feed"
    run.generate(cfg, ref)
    executors.generate(cfg, out, workers=2, feed=True)
    assert feed.LAST_RUN_SECONDS["simulate"] > 0
    assert "protocols (first batch, in the driver)" in feed.LAST_RUN_SECONDS  # handed to the physics process
    for i in range(2):
        with Recording(ref / f"shard-{i:05d}.h5") as ra, Recording(out / f"shard-{i:05d}.h5") as rb:
            assert ra.episode_ids == rb.episode_ids
            assert max(float(ra.read(ep, "force").max()) for ep in ra.episode_ids) > 1.0  # the staircase reaches 2 N
            for ep in ra.episode_ids:
                assert ra.channels(ep) == rb.channels(ep)
                for ch in ra.channels(ep):
                    assert ra.read(ep, ch).tobytes() == rb.read(ep, ch).tobytes(), (ep, ch)


def test_feed_schedules_mixed_lengths_short_first_and_writes_the_serial_files(tmp_path, monkeypatch):
    """Mixed episode lengths (1 and 4 Hz, one cycle: 120 and 45 samples, more than LENGTH_SPLIT apart): `_schedule`
    puts the short episodes of every shard first, then the long ones in windows of shards, so a shard's episodes
    come in two batches (shard 0 only short ones, shard 1 only long ones, shard 4 one short episode: its window of
    long ones steps nothing); the feed
    still writes the serial loop's files: same episodes in the same order, same bytes, same manifest."""
    from simulate.generation import feed

    mixed = load_scene("cnt_pdms", ["protocol.frequencies_hz=[1.0,4.0]", "protocol.cycles=1", "pad.taxels_x=3",
                                    "pad.taxels_y=2", "generation.episodes=9", "generation.episodes_per_shard=2",
                                    "generation.root_seed=3"])
    from sensors.data.manifest import episode_seed

    seeds = [episode_seed(3, k) for k in range(9)]
    assert [p.n_samples for p in run.episode_protocols(mixed, seeds, list(range(9)))] == [45, 45, 120, 120, 120, 45, 45, 120, 45]
    monkeypatch.setattr(feed, "FEED_WORLDS", 3)  # short batches of <= 3 x 1.25 episodes; long windows of ~1 long one
    sched = feed._schedule(mixed, [0, 1, 2, 3, 4], 4)
    short, long = feed.Select(False, 60), feed.Select(True, 60)
    assert sched == [([0, 1, 2], short), ([3, 4], short), ([0, 1], long), ([2], long), ([3], long), ([4], long)]
    monkeypatch.setattr(feed, "LENGTH_SCHEDULE", False)  # the A/B switch: whole shards
    assert all(sel is None for _, sel in feed._schedule(mixed, [0, 1, 2, 3, 4], 4))
    monkeypatch.setattr(feed, "LENGTH_SCHEDULE", True)
    ref, out = tmp_path / "serial", tmp_path / "feed"
    run.generate(mixed, ref)
    seen, made, new_turns = [], [], feed.new_turns
    monkeypatch.setattr(feed, "new_turns", lambda: made.append(new_turns()) or made[-1])
    executors.generate(mixed, out, workers=2, feed=True, on_shard=lambda s, n, skip: seen.append((s, n)))
    assert [(b["select"], b["episodes"], b["max_samples"]) for b in feed.LAST_RUN_BATCHES] == [
        ("short <= 60 samples", 3, 45), ("short <= 60 samples", 2, 45), ("long > 60 samples", 2, 120),
        ("long > 60 samples", 1, 120), ("long > 60 samples", 1, 120), ("long > 60 samples", 0, 0)]  # shard 4: none
    assert sorted(seen) == [(0, 2), (1, 2), (2, 2), (3, 2), (4, 1)]
    assert "physics: waiting for the GPU turn" in feed.LAST_RUN_SECONDS  # six batches, two processes, in turns
    assert made and not os.path.exists(made[0])  # the turn file is gone
    a, b = _episodes(ref, 5), _episodes(out, 5)
    assert list(a) == list(b) == [f"ep-{k:06d}" for k in range(9)]
    for ep in a:
        assert list(a[ep]) == list(b[ep])
        for ch in a[ep]:
            assert a[ep][ch].dtype == b[ep][ch].dtype and a[ep][ch].tobytes() == b[ep][ch].tobytes(), (ep, ch)
    for i in range(5):
        with Recording(shard_path(ref, i)) as ra, Recording(shard_path(out, i)) as rb:
            assert ra.episode_ids == rb.episode_ids
            for ep in ra.episode_ids:
                np.testing.assert_equal(rb.episode_attrs(ep), ra.episode_attrs(ep))
    ma, mb = read_manifest(ref), read_manifest(out)
    assert [s["episode_seeds"] for s in mb["shards"]] == [s["episode_seeds"] for s in ma["shards"]]
    assert ma["splits"] == mb["splits"] and ma["config_sha256"] == mb["config_sha256"]


def test_physics_processes_started_ahead_are_taken_by_the_feed_or_stopped(cfg, serial, tmp_path, monkeypatch):
    """The CLI starts the feed's physics processes before its engine choice where the feed is likely
    (`feed.feed_likely`: one NVIDIA GPU, mujoco_warp, a worlds protocol, no CPU flag); `generate_feed` takes them and
    writes the same files; a run that does not use the feed stops them (terminated, not waited for)."""
    import os as _os

    from simulate.contact import mujoco_warp as contact_mjw
    from simulate.generation import feed

    # the judgement, without CUDA: no /proc/driver/nvidia here, then one GPU faked
    assert not feed.feed_likely(cfg, "auto", "auto", "warp", "local") or _os.path.isdir("/proc/driver/nvidia/gpus")
    real_listdir = _os.listdir
    monkeypatch.setattr(feed.os, "listdir", lambda p: ["0000:01:00.0"] if p == "/proc/driver/nvidia/gpus" else real_listdir(p))
    monkeypatch.setattr(contact_mjw, "available", lambda: True)
    assert feed.feed_likely(cfg, "auto", "auto", "warp", "local")
    assert not feed.feed_likely(cfg, "auto", "auto", "warp", "local", 1)  # one worker: the serial loop
    for args in (("mujoco", "auto", "warp", "local"), ("auto", "cpu", "warp", "local"), ("auto", "auto", "numpy", "local"),
                 ("auto", "auto", "warp", "ray")):
        assert not feed.feed_likely(cfg, *args), args
    ntype = load_scene("ntype")  # press_stroke: its worlds step in the physics processes too
    assert feed.feed_likely(ntype, "auto", "auto", "warp", "local") and not feed.stage_in_driver(ntype)
    paper = load_scene("ntype", ["protocol.kind=element_loads"])  # no worlds: its contact stage runs in the driver
    assert feed.stage_in_driver(paper) and not feed.feed_likely(paper, "auto", "auto", "warp", "local")
    # taken by the feed: the same files as the serial loop
    feed.prestart_physics()
    pool = feed._PRESTARTED
    assert pool is not None
    out = tmp_path / "ahead"
    executors.generate(cfg, out, workers=2, feed=True)
    assert feed._PRESTARTED is None
    _assert_same_dataset(serial, out, 4)
    # not taken (a per-shard pool runs instead): stopped
    feed.prestart_physics()
    procs = list(feed._PRESTARTED._processes.values())
    assert procs
    executors.generate(cfg, tmp_path / "pool", workers=2, feed=False)
    assert feed._PRESTARTED is None and all(not p.is_alive() for p in procs)


def test_cli_failure_after_the_physics_started_ahead_stops_them(monkeypatch, tmp_path):
    # `generate` starts the physics processes before its engine choice; an error after that (here: mujoco_warp asked
    # for where it is not installed, or a device that does not exist) stops them on the way out
    from typer.testing import CliRunner

    from piezotwin.cli import app
    from simulate.generation import feed

    started = []
    real = feed.prestart_physics

    def prestart():
        real()
        started.extend(feed._PRESTARTED._processes.values())

    monkeypatch.setattr(feed, "feed_likely", lambda *a: True)
    monkeypatch.setattr(feed, "prestart_physics", prestart)
    res = CliRunner().invoke(app, ["generate", "cnt_pdms", "-o", str(tmp_path / "x"), "--episodes", "2",
                                   "--physics", "mujoco_warp", "--device", "cuda:7"])
    assert res.exit_code == 2, res.output
    assert started and feed._PRESTARTED is None and all(not p.is_alive() for p in started)


def test_a_driver_failure_leaves_no_physics_block_behind(cfg, tmp_path, monkeypatch):
    """The physics processes hand each batch's sensordata over in a shared block that the driver unlinks once it
    has read it; a driver that fails first (here: its first batch's sensor stage) unlinks the block of the batch in
    hand and those of the batches stepped ahead, instead of leaving them in /dev/shm for the resource tracker."""
    from concurrent.futures import ProcessPoolExecutor

    from simulate.generation import feed

    monkeypatch.setattr(feed, "FEED_WORLDS", 4)  # a ramp of >= 1, >= 2 episodes, then >= 4: the two physics
    # processes step batches 0 and 1 before the driver takes batch 0
    futures = []
    real_submit = ProcessPoolExecutor.submit

    def submit(self, fn, *a, **k):
        fut = real_submit(self, fn, *a, **k)
        if fn is feed.step_worlds:
            futures.append(fut)
        return fut

    monkeypatch.setattr(ProcessPoolExecutor, "submit", submit)

    def fail(self, shards, stepped=None):
        futures[1].result()  # the batch stepped ahead is back too (its block made)
        raise RuntimeError("sensor stage failed")

    monkeypatch.setattr(feed.Producer, "batch", fail)
    with pytest.raises(RuntimeError, match="sensor stage failed"):
        executors.generate(cfg, tmp_path / "out", workers=2, feed=True)
    names = [h[0] for fut in futures if fut.done() and not fut.cancelled() and fut.exception() is None
             for h in fut.result()[1].values() if isinstance(h[0], str)]
    assert len(names) >= 2  # the batch in hand and one stepped ahead handed blocks over
    assert not [n for n in names if (Path("/dev/shm") / n.lstrip("/")).exists()]

"""The GPU feed's first batch streamed (simulate/generation/feed.py: `Stream`, `step_worlds(mailbox=...)`): the
load field and sensor chain of a length group run in time chunks while its worlds step, carrying the chain's
state from chunk to chunk; the channels equal those of the group's own run, bit for bit (fabric_1, C MuJoCo
here; the MuJoCo Warp twin is marked slow)."""

from multiprocessing import shared_memory

import numpy as np
import pytest

from scenes import load_scene
from sensors.data.manifest import episode_seed
from simulate.generation import feed, run

# fabric_1's staircase, shortened (the same kind, controls and sensor; two levels, 1 s dwells)
SHORT = ["protocol.stair_return_points_n=[1.0, 2.0]", "protocol.stair_dwell_s=1 s", "generation.episodes=3",
         "generation.episodes_per_shard=2", "generation.root_seed=7"]


def _channels(packs, pool):
    got = {}
    for p in packs:
        pieces = p.arrays({n: pool.blocks[n].buf for n in p.block_names})
        for ep_id, _, piece, row in p.episodes:
            got[ep_id] = {n: np.array(pieces[piece][n][row] if spec[3] else pieces[piece][n]) for n, spec in p.specs.items()}
        pieces = None
    return got


def test_stream_in_time_chunks_equals_the_groups_own_run():
    """A physics task's sensordata in a shared block, handed to a `Stream` in uneven time chunks (as the worlds'
    chunks come in), then packed by `iter_produce`: every channel equals the plain path's, bit for bit."""
    from simulate.contact.load_field import simulate_sensors

    cfg = load_scene("fabric_1", SHORT)
    sensor = run.make_sensor(cfg, "warp", "cpu")
    gids = [0, 1, 2]
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in gids]
    protos = run.episode_protocols(cfg, seeds, gids)
    (n, idx), = run.length_groups(protos)
    made = []

    def alloc(shape):
        made.append(shared_memory.SharedMemory(create=True, size=8 * (int(np.prod(shape)) + shape[0] * shape[1])))
        return np.ndarray(shape, np.float64, buffer=made[0].buf)

    sens, target = simulate_sensors(cfg, protos, 1, alloc)
    np.ndarray(target.shape, np.float64, buffer=made[0].buf, offset=sens.nbytes)[...] = target
    layout = [(0, sens.dtype.str, sens.shape), (sens.nbytes, "<f8", target.shape)]
    shape, sens = sens.shape, None
    st = feed.Stream(cfg, sensor, made[0].name, shape, idx, [seeds[i] for i in idx])
    for k in (1, 2, 7, n // 2, n // 2 + 1, n - 3):  # uneven chunks, the rest in finish
        st.advance(k)
    pool = feed.BlockPool()
    try:
        got = _channels(feed.produce(cfg, [0, 1], sensor, stepped=(protos, {n: (made[0].name, layout)}), pool=pool,
                                     streams={n: st}), pool)
        assert st.fed == n
        made[0].close()  # iter_produce unlinked it
        ref = run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in gids], sensor, indices=gids)
        assert max(float(r.channels["force"].data.max()) for r in ref) > 1.0  # the staircase reaches 2 N
        for r in ref:
            assert list(got[r.ep_id]) == list(r.channels)
            for name, c in r.channels.items():
                np.testing.assert_array_equal(got[r.ep_id][name], c.data, err_msg=f"{r.ep_id} {name}")
    finally:
        pool.close()


def test_feed_streams_its_first_batch_and_writes_the_serial_files(tmp_path):
    """The whole feed (physics process with a mailbox, driver streaming, writers) against the serial loop: the
    same bytes in every channel, and the streamed part timed."""
    from sensors.data.recording import Recording
    from simulate.generation import executors

    cfg = load_scene("fabric_1", SHORT)
    ref, out = tmp_path / "serial", tmp_path / "feed"
    run.generate(cfg, ref)
    executors.generate(cfg, out, workers=2, feed=True)
    assert "simulate (first batch, while it steps)" in feed.LAST_RUN_SECONDS
    for i in range(2):
        with Recording(ref / f"shard-{i:05d}.h5") as ra, Recording(out / f"shard-{i:05d}.h5") as rb:
            assert ra.episode_ids == rb.episode_ids
            for ep in ra.episode_ids:
                assert ra.channels(ep) == rb.channels(ep)
                for ch in ra.channels(ep):
                    assert ra.read(ep, ch).tobytes() == rb.read(ep, ch).tobytes(), (ep, ch)


@pytest.mark.slow
def test_stream_on_mujoco_warp_cpu_equals_unstreamed(tmp_path, monkeypatch):
    """On MuJoCo Warp (Warp's CPU device) the worlds hand their samples on chunk by chunk: the streamed feed
    writes the bytes of the feed without streaming."""
    pytest.importorskip("mujoco_warp")
    from sensors.data.recording import Recording
    from simulate.generation import executors

    cfg = load_scene("fabric_1", SHORT + ["generation.physics=mujoco_warp", "generation.device=cpu"])
    a, b = tmp_path / "streamed", tmp_path / "plain"
    executors.generate(cfg, a, workers=2, feed=True)
    assert "simulate (first batch, while it steps)" in feed.LAST_RUN_SECONDS
    monkeypatch.setattr(feed, "STREAM_FIRST_BATCH", False)
    executors.generate(cfg, b, workers=2, feed=True)
    for i in range(2):
        with Recording(a / f"shard-{i:05d}.h5") as ra, Recording(b / f"shard-{i:05d}.h5") as rb:
            for ep in ra.episode_ids:
                for ch in ra.channels(ep):
                    assert ra.read(ep, ch).tobytes() == rb.read(ep, ch).tobytes(), (ep, ch)


@pytest.mark.gpu
def test_stream_as_the_worlds_step_equals_the_groups_own_run(gpu_device, monkeypatch):
    """MuJoCo Warp on the device under test, the stream advanced from the worlds' own progress calls (small
    chunks: several per episode) while they step; against the plain path on the same sensordata (one physics run
    for both: GPU atomics need not repeat bit for bit): every channel bit for bit."""
    pytest.importorskip("mujoco_warp")
    from simulate.contact import load_field as contact
    from simulate.contact import mujoco_warp as contact_mjw

    dev = "cpu" if gpu_device == "cpu" else "cuda"
    cfg = load_scene("fabric_1", SHORT + ["generation.physics=mujoco_warp", f"generation.device={dev}"])
    sensor = run.make_sensor(cfg, "warp", contact.physics_engine(cfg)[1])
    gids = [0, 1, 2]
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in gids]
    protos = run.episode_protocols(cfg, seeds, gids)
    (n, idx), = run.length_groups(protos)
    monkeypatch.setattr(contact_mjw, "CHUNK_BYTES", 3 * 4 * 500)  # a few samples per chunk
    made, streams, calls = [], {}, []

    def alloc(shape):
        made.append(shared_memory.SharedMemory(create=True, size=8 * (int(np.prod(shape)) + shape[0] * shape[1])))
        streams[n] = feed.Stream(cfg, sensor, made[0].name, shape, idx, [seeds[i] for i in idx])
        return np.ndarray(shape, np.float64, buffer=made[0].buf)

    def progress(k):
        calls.append(k)
        streams[n].advance(k)

    sens, target = contact.simulate_sensors(cfg, protos, 1, alloc, progress)
    assert len(calls) > 3 and calls[-1] == n  # handed on chunk by chunk
    np.ndarray(target.shape, np.float64, buffer=made[0].buf, offset=sens.nbytes)[...] = target
    layout = [(0, sens.dtype.str, sens.shape), (sens.nbytes, "<f8", target.shape)]
    physics = (sens.copy(), target.copy())
    sens = None
    pool = feed.BlockPool()
    try:
        got = _channels(feed.produce(cfg, [0, 1], sensor, stepped=(protos, {n: (made[0].name, layout)}), pool=pool,
                                     streams=streams), pool)
        made[0].close()
        monkeypatch.setattr(contact, "simulate_sensors", lambda *a: physics)
        ref = run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in gids], sensor, indices=gids)
        assert max(float(r.channels["force"].data.max()) for r in ref) > 1.0
        for r in ref:
            for name, c in r.channels.items():
                np.testing.assert_array_equal(got[r.ep_id][name], c.data, err_msg=f"{r.ep_id} {name}")
    finally:
        pool.close()

"""Taxel fields sent off the device as their non-zero blocks (simulate/contact/field_blocks.py and its kernels in
load_field_kernels): the kernels equal the numpy reference, episode rows read back byte for byte (-0.0, NaN and
float32 underflow included), and the GPU feed's pack and writers give the files of the dense path."""

import numpy as np
import pytest
import warp as wp

from simulate.contact.field_blocks import BlockSparse, blocks_of


def _field(shape, seed=0):
    """A float64 field mostly zero, with a few loaded taxels per episode and the byte edge cases."""
    rng = np.random.default_rng(seed)
    a = np.zeros(shape)
    E, T, N = shape[:3]
    for e in range(E):
        n = rng.integers(0, N)
        a[e, :, n] = rng.normal(0, 1, (T, *shape[3:]))
    if E > 2:
        a[1, T - 1, -1] = -0.0  # float32 -0.0: a non-zero byte, so its block is kept
        a[2, 0, 0] = -1e-50  # underflows to float32 -0.0: kept
        a[2, T - 1, N // 2] = 1e-50  # underflows to +0.0: not a reason to keep its block
        a[0, T - 1, 1] = np.nan
    return a


@pytest.mark.parametrize("shape,block", [((4, 7, 37), 16), ((5, 3, 10, 2), 4), ((3, 6, 8), 16), ((0, 5, 20), 16)])
def test_device_blocks_equal_the_numpy_reference_and_read_back_byte_for_byte(shape, block, monkeypatch):
    from sensors.warp_setup import init_warp
    from simulate.contact import field_blocks
    from simulate.contact.load_field_kernels import fields_f32_blocks_to_host

    init_warp()
    monkeypatch.setattr(field_blocks, "SPARSE_MAX_SHARE", 1.0)  # always as blocks
    dense64 = _field(shape)
    dense = dense64.astype(np.float32)
    flat = wp.array(dense64.reshape(-1), dtype=wp.float64, device="cpu")
    asked = (shape[0], shape[1], -1, *shape[3:]) if shape[0] else shape  # -1: the taxels from the size, as a reshape
    got = fields_f32_blocks_to_host({"f": flat}, {"f": asked}, block)["f"]
    ref = blocks_of(dense, block)
    assert isinstance(got, BlockSparse) and got.shape == dense.shape
    np.testing.assert_array_equal(got.index, ref.index)
    assert got.blocks.tobytes() == ref.blocks.tobytes()
    assert np.asarray(got).tobytes() == dense.tobytes()  # -0.0 and NaN bytes included
    for r in range(shape[0]):
        assert got[r].tobytes() == dense[r].tobytes()
    if shape[0] > 2:
        if shape[2] >= 2 * block:
            assert got.stored_nbytes < dense.nbytes  # a few loaded taxels: most blocks left behind
        sub = got[[0, 2]]
        assert sub.shape == (2, *dense.shape[1:]) and np.asarray(sub).tobytes() == dense[[0, 2]].tobytes()
        assert np.asarray(got[1:]).tobytes() == dense[1:].tobytes()
        assert np.asarray(got.copy()).tobytes() == dense.tobytes()


def test_underflow_to_plus_zero_leaves_a_block_behind_and_to_minus_zero_keeps_it():
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field_kernels import fields_f32_blocks_to_host

    init_warp()
    for value, kept in ((1e-50, 0), (-1e-50, 1), (0.0, 0), (-0.0, 1)):
        a = np.zeros((2, 3, 20))
        a[1, 2, 17] = value
        got = fields_f32_blocks_to_host({"f": wp.array(a.reshape(-1), dtype=wp.float64, device="cpu")}, {"f": (2, 3, -1)})["f"]
        assert len(got.index) == kept and np.asarray(got).tobytes() == a.astype(np.float32).tobytes(), value


def test_a_field_loaded_on_most_blocks_comes_whole(monkeypatch):
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field_kernels import fields_f32_blocks_to_host

    init_warp()
    dense64 = np.random.default_rng(3).normal(0, 1, (3, 4, 40))
    flat = wp.array(dense64.reshape(-1), dtype=wp.float64, device="cpu")
    got = fields_f32_blocks_to_host({"f": flat, "z": wp.zeros(3 * 4 * 40 * 2, dtype=wp.float64, device="cpu")},
                                    {"f": (3, 4, -1), "z": (3, 4, -1, 2)})
    assert isinstance(got["f"], np.ndarray) and got["f"].tobytes() == dense64.astype(np.float32).tobytes()
    assert isinstance(got["z"], BlockSparse) and got["z"].stored_nbytes == 0 and got["z"].shape == (3, 4, 40, 2)
    assert not np.asarray(got["z"]).any() and got["z"][2].shape == (4, 40, 2)


def _device_fields_on_cpu(monkeypatch):
    """A 7-episode cnt_pdms scene (2-episode shards, 6 x 6 taxels) sliced as on MuJoCo Warp with its load field made
    by the Warp kernels and left on Warp's CPU device (the engine name patched over C MuJoCo's physics, run once), so
    the taxel fields leave the device through `fields_f32_blocks_to_host`: (cfg, sensor)."""
    from scenes import load_scene
    from simulate.contact import load_field as contact
    from simulate.generation import run

    cfg = load_scene("cnt_pdms", ["protocol.frequencies_hz=[2.0]", "protocol.cycles=1", "pad.taxels_x=6", "pad.taxels_y=6",
                                  "sensor.readout=taxel", "generation.record=[time,deformation,pressure,shear,force_taxel,adc]",
                                  "generation.episodes=7", "generation.episodes_per_shard=2", "generation.root_seed=3"])
    sensor = run.make_sensor(cfg, "warp", "cpu")
    physics, real, c_engine, stepping = [], contact.simulate_sensors, contact.physics_engine, []
    monkeypatch.setattr(run, "physics_engine", lambda cfg: ("mujoco_warp", "cpu"))
    # the load field by the Warp kernels, the physics by C MuJoCo
    monkeypatch.setattr(contact, "physics_engine", lambda cfg: c_engine(cfg) if stepping else ("mujoco_warp", "cpu"))

    def once(*a):
        if not physics:
            stepping.append(1)
            physics.append(real(*a))
            stepping.clear()
        return physics[0]

    monkeypatch.setattr(contact, "simulate_sensors", once)
    return cfg, sensor


def test_feed_packs_block_fields_and_writes_the_dense_files(monkeypatch, tmp_path):
    """The GPU feed's producer with fields on the device: packed as blocks (4-taxel blocks, always sparse) into a
    BlockPool or pickled, they read back as the dense path's bytes, and the writer makes a file with the dense
    path's content hash."""
    from sensors.data.recording import Recording
    from simulate.contact import field_blocks
    from simulate.generation import feed

    cfg, sensor = _device_fields_on_cpu(monkeypatch)

    def packs_with(share, pool):
        monkeypatch.setattr(field_blocks, "SPARSE_MAX_SHARE", share)
        return feed.produce(cfg, [0, 1, 2, 3], sensor, pool=pool)

    monkeypatch.setattr(field_blocks, "FIELD_BLOCK", 4)
    pool = feed.BlockPool()
    try:
        dense = packs_with(-1.0, None)  # every field whole (more than -100 % of its blocks loaded)
        sparse = packs_with(1.0, pool)
        pickled = packs_with(1.0, None)
        assert all(not p.sparse[0] for p in dense)
        assert all(set(s) == {"deformation", "pressure", "shear"} for p in sparse for s in p.sparse)
        held = sum(p.nbytes for p in sparse)
        assert held < sum(p.nbytes for p in dense)  # the unloaded blocks stayed behind
        for d, s, k in zip(dense, sparse, pickled):
            da, sa = d.arrays({}), s.arrays({n: pool.blocks[n].buf for n in s.block_names})
            ka = k.arrays({})
            for (_, _, piece, row), (_, _, piece_s, row_s) in zip(d.episodes, s.episodes):
                for n, spec in d.specs.items():
                    want = da[piece][n][row] if spec[3] else da[piece][n]
                    for got in (sa[piece_s][n], ka[piece_s][n]):
                        assert (got[row_s] if spec[3] else got).tobytes() == want.tobytes(), n
            sa = None
        # the pack's estimate (populated ahead) plans a block field at SPARSE_MAX_SHARE of its dense bytes: with every
        # field as blocks (share 1) it covers what the pieces hold, and no more than the whole fields
        need = feed.batch_pack_bytes(cfg, sensor, list(range(7)))
        held = sum(int(np.prod(shape)) * np.dtype(dt).itemsize for p in sparse for b in p.blocks for _, dt, shape in b[1].values())
        whole = sum(a.nbytes for p in dense for piece in p.pieces for n, a in piece.items() if n != "time")
        assert held <= need <= whole
        attrs, mjcf = sensor.attrs(), "<mujoco/>"
        for name, packs, bufs in (("dense", dense, {}), ("sparse", sparse, None)):
            out = tmp_path / name
            out.mkdir()
            for p in packs:
                feed.write_packed_shard(cfg, str(out), p, attrs, mjcf)
        for i in range(4):
            with Recording(tmp_path / "dense" / f"shard-{i:05d}.h5") as a, Recording(tmp_path / "sparse" / f"shard-{i:05d}.h5") as b:
                assert a.content_sha256 == b.content_sha256
                assert b.compute_content_sha256() == a.content_sha256
    finally:
        pool.close()

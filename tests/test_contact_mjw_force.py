"""The force-controlled protocols on MuJoCo Warp against C MuJoCo: fabric staircases and the velostat
compression-tester kinds (cnt_pdms' position-controlled press: tests/test_contact_mjw.py).

Both engines run the same MJCF and controls; MuJoCo Warp computes in float32. The forces at stake are small
(fabric 0.1-2 N on a stiff thin pad: 1-15 um deep; velostat 1-15 N: 1-20 um), which is why MuJoCo Warp runs box-box
pairs through its box-box primitive (simulate/contact/mujoco_warp.py: its convex collider missed contacts shallower
than ~1e-5 m). Measured on Warp's CPU device (short episodes below): contact force within 2.6e-5 (fabric_1) and
2.8e-5 (velostat) of full scale, positions within 1e-9 m. Checked here: 2e-3 of full scale (as for cnt_pdms),
positions within 1e-7 m, the contact found wherever the pad carries load, and the commanded force reached.
The Warp-CPU runs compile MuJoCo Warp's kernels for each scene (~1.5 min cold): marked slow; the CUDA runs: gpu.
"""

import numpy as np
import pytest

from scenes import load_scene
from simulate.contact.load_field import simulate_sensors
from simulate.contact.mujoco_warp import available
from simulate.generation.run import episode_protocols

needs_mjw = pytest.mark.skipif(not available(), reason="mujoco_warp not installed (extra: gpu)")

# short versions of the default protocols (same kinds, controls and contact model; fewer levels, shorter holds)
SHORT = {
    "fabric_1": ["protocol.stair_return_points_n=[1.0, 2.0]", "protocol.stair_dwell_s=1 s"],
    "velostat": ["protocol.duration_s=20", "protocol.step_hold_s=1", "protocol.hold_max_s=6", "protocol.staircase_max_n=4"],
}


def _compare(family: str, device: str, n_episodes: int) -> None:
    dev = "cpu" if device == "cpu" else "cuda"
    cfg = load_scene(family, SHORT[family])
    cfg_w = load_scene(family, SHORT[family] + ["generation.physics=mujoco_warp", f"generation.device={dev}"])
    protos = episode_protocols(cfg, list(range(n_episodes)), list(range(n_episodes)))
    a, ta = simulate_sensors(cfg, protos)
    b, tb = simulate_sensors(cfg_w, protos)
    np.testing.assert_array_equal(ta, tb)
    fa, fb = a[..., 4:7], b[..., 4:7]
    full = cfg.protocol.amplitude_max
    assert np.abs(fa[..., 2]).max() > 0.5 * ta.max()  # the episodes press: a loaded contact is compared
    assert np.abs(fa - fb).max() < 2e-3 * full
    np.testing.assert_allclose(b[..., 0:3], a[..., 0:3], atol=1e-7)
    loaded = -fa[..., 2] > 0.01 * full
    assert (b[..., 3][loaded] > 0).all()  # MuJoCo Warp finds the contact wherever C MuJoCo carries load
    # force control: the pad carries the commanded force once the ramps settle (holds), on both engines
    hold = np.abs(np.diff(ta, axis=1, prepend=0.0)) < 1e-9
    assert np.abs(-fb[..., 2] - ta)[hold].max() < 0.02 * full


@needs_mjw
@pytest.mark.slow
@pytest.mark.parametrize("family", ["fabric_1", "velostat"])
def test_force_control_mjw_cpu_matches_c_mujoco(family):
    _compare(family, "cpu", 2)


@needs_mjw
@pytest.mark.gpu
@pytest.mark.parametrize("family", ["fabric_1", "velostat"])
def test_force_control_mjw_cuda_matches_c_mujoco(family, gpu_device):
    _compare(family, gpu_device, 32)


def _velostat_feed_paths(device: str, n_episodes: int, monkeypatch) -> None:
    """velostat through the GPU path's producer (`simulate_episodes` on MuJoCo Warp): the sensor fed the load field
    left on the device (`VelostatSensor.run_device`) against the same physics with the field copied to the host
    first (the session-8 path): every recorded channel bit for bit but force and contact_xy (float64 sums in
    another order, rounded to float32: 1 ulp, or 1e-12 N / m where the value is ~0 by cancellation), and unit
    (the cell under those centroids: the same here). The taxel fields are recorded too (the preset records every
    channel): rounded to float32 on the device on the first path, on the host on the second."""
    from sensors.data.manifest import episode_seed
    from sensors.velostat.model import VelostatSensor
    from simulate.contact import load_field as contact
    from simulate.generation import run

    dev = "cpu" if device == "cpu" else "cuda"
    cfg = load_scene("velostat", SHORT["velostat"] + ["generation.physics=mujoco_warp", f"generation.device={dev}",
                                                      f"generation.episodes={n_episodes}"])
    physics, real = [], contact.simulate_sensors  # one physics run for both paths
    monkeypatch.setattr(contact, "simulate_sensors", lambda *a: physics[0] if physics else physics.append(real(*a)) or physics[0])
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in range(n_episodes)]
    ids = [f"ep-{k:06d}" for k in range(n_episodes)]
    sensor = run.make_sensor(cfg, "warp", contact.physics_engine(cfg)[1])
    got = run.simulate_episodes(cfg, seeds, ids, sensor, indices=list(range(n_episodes)))
    monkeypatch.setattr(VelostatSensor, "device_load", False)
    ref = run.simulate_episodes(cfg, seeds, ids, sensor, indices=list(range(n_episodes)))
    assert max(float(r.channels["force"].data.max()) for r in ref) > 1.0  # the presses reach newtons
    for a, b in zip(got, ref):
        assert list(a.channels) == list(b.channels)
        for n, c in b.channels.items():
            if n in ("force", "contact_xy"):  # atol: a centroid at ~1e-16 m (cancellation) has no relative precision
                np.testing.assert_allclose(a.channels[n].data, c.data, rtol=2.4e-7, atol=1e-12, err_msg=f"{b.ep_id} {n}")
            else:
                np.testing.assert_array_equal(a.channels[n].data, c.data, err_msg=f"{b.ep_id} {n}")


@needs_mjw
@pytest.mark.slow
def test_velostat_device_sensor_path_equals_host_path_mjw_cpu(monkeypatch):
    _velostat_feed_paths("cpu", 2, monkeypatch)


@needs_mjw
@pytest.mark.gpu
def test_velostat_device_sensor_path_equals_host_path_cuda(gpu_device, monkeypatch):
    _velostat_feed_paths(gpu_device, 16, monkeypatch)


def _velostat_feed_overlap(device: str, monkeypatch) -> None:
    """velostat's feed producer on MuJoCo Warp (7 episodes, 2-episode shards, 2-episode slices): each slice packed
    while the next runs (`feed.PACK_OVERLAP`; on CUDA its outputs in the other set of page-locked staging
    buffers) gives bit for bit the shards packed one after the other and the plain path's channels, in the same
    shard order and episode order, from one physics run."""
    from sensors.data.manifest import episode_seed
    from simulate.contact import load_field as contact
    from simulate.generation import feed, run

    dev = "cpu" if device == "cpu" else "cuda"
    n = 7
    cfg = load_scene("velostat", SHORT["velostat"] + ["generation.physics=mujoco_warp", f"generation.device={dev}",
                                                      f"generation.episodes={n}", "generation.episodes_per_shard=2"])
    physics, real = [], contact.simulate_sensors  # one physics run for every path
    monkeypatch.setattr(contact, "simulate_sensors", lambda *a: physics[0] if physics else physics.append(real(*a)) or physics[0])
    monkeypatch.setattr(run, "SENSOR_SLICE", 2)
    sensor = run.make_sensor(cfg, "warp", contact.physics_engine(cfg)[1])
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in range(n)]
    ref = run.simulate_episodes(cfg, seeds, [f"ep-{k:06d}" for k in range(n)], sensor, indices=list(range(n)))
    assert max(float(r.channels["force"].data.max()) for r in ref) > 1.0  # the presses reach newtons
    runs = {}
    for overlap in (False, True):
        monkeypatch.setattr(feed, "PACK_OVERLAP", overlap)
        pool = feed.BlockPool()
        try:
            got, order = {}, []
            for p in feed.iter_produce(cfg, [0, 1, 2, 3], sensor, pool=pool):
                order.append((p.shard, [e[0] for e in p.episodes], [e[1]["seed"] for e in p.episodes]))
                pieces = p.arrays({b: pool.blocks[b].buf for b in p.block_names})
                for ep_id, _, piece, row in p.episodes:
                    got[ep_id] = {c: np.array(pieces[piece][c][row] if spec[3] else pieces[piece][c])
                                  for c, spec in p.specs.items()}
                pieces = None
            runs[overlap] = (got, order)
        finally:
            pool.close()
    assert runs[True][1] == runs[False][1] and [o[0] for o in runs[True][1]] == [0, 1, 2, 3]
    for r in ref:
        for got, _ in runs.values():
            assert list(got[r.ep_id]) == list(r.channels)
            for c, ch in r.channels.items():
                np.testing.assert_array_equal(got[r.ep_id][c], ch.data, err_msg=f"{r.ep_id} {c}")


@needs_mjw
@pytest.mark.slow
def test_velostat_feed_pack_overlap_same_bytes_mjw_cpu(monkeypatch):
    _velostat_feed_overlap("cpu", monkeypatch)


@needs_mjw
@pytest.mark.gpu
def test_velostat_feed_pack_overlap_same_bytes_cuda(gpu_device, monkeypatch):
    _velostat_feed_overlap(gpu_device, monkeypatch)

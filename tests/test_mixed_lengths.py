"""Episodes of mixed lengths on MuJoCo Warp: small length groups merged into one padded batch of worlds
(simulate.contact.load_field.world_groups / simulate_sensors_padded), large ones apart; feed batches sized per length."""

import numpy as np
import pytest

from scenes import load_scene
from simulate.contact import load_field
from simulate.contact.load_field import (
    simulate_sensors,
    simulate_sensors_padded,
    world_groups,
)
from simulate.contact.mujoco_warp import available

MIX = [170, 320, 620, 3020]  # samples per episode of the default 2 / 1 / 0.5 / 0.1 Hz mix


def _lengths(runs):
    return [[n for n, _ in r] for r in runs]


def test_world_groups_merge_small_groups_and_keep_large_ones_apart():
    groups = lambda c: [(n, list(range(c))) for n in MIX]
    assert _lengths(world_groups(groups(16))) == [MIX]  # a few worlds: one padded batch
    assert _lengths(world_groups(groups(32768))) == [[n] for n in MIX]  # GPU-filling groups: apart
    for c in (16, 1024, 8192, 32768):  # every group exactly once, in order
        assert [g for r in world_groups(groups(c)) for g in r] == groups(c)
    # the model's choice is never slower (in the model) than either extreme
    t = lambda runs: sum(max(n for n, _ in r) * (load_field.STEP_S_FLOOR + sum(len(i) for _, i in r) / load_field.WORLD_STEPS_PER_S) for r in runs)
    for c in (16, 1024, 8192, 32768):
        g = groups(c)
        assert t(world_groups(g)) <= min(t([g]), t([[x] for x in g])) + 1e-12
    assert world_groups([]) == []


def test_physics_runs_c_engine_keeps_one_rollout_per_length():
    from simulate.generation.run import episode_protocols, physics_runs

    cfg = load_scene("cnt_pdms")
    protos = episode_protocols(cfg, list(range(12)))
    assert all(len(r) == 1 for r in physics_runs(cfg, protos))  # the CPU path is unchanged


def test_feed_batches_scale_with_the_lengths(monkeypatch):
    from simulate.generation import feed

    single = load_scene("cnt_pdms", ["protocol.frequencies_hz=[0.5]"])
    mixed = load_scene("cnt_pdms")
    assert feed.feed_worlds(single) == feed.FEED_WORLDS
    monkeypatch.setattr(feed, "BATCH_RAM_FRACTION", 1.0)
    assert feed.feed_worlds(mixed) == 4 * feed.FEED_WORLDS  # FEED_WORLDS worlds in each of 4 lengths
    monkeypatch.setattr(feed, "BATCH_RAM_FRACTION", 1e-9)
    assert feed.feed_worlds(mixed) == feed.FEED_WORLDS  # never below the single-length batch


def _padded_equals_bucketed(device: str, exact: bool) -> None:
    dev = "cpu" if device == "cpu" else "cuda"
    cfg = load_scene("cnt_pdms", ["protocol.frequencies_hz=[2.0, 1.0]", "protocol.cycles=1", "pad.taxels_x=4",
                                  "pad.taxels_y=4", "generation.physics=mujoco_warp", f"generation.device={dev}"])
    from simulate.generation.run import episode_protocols, length_groups

    protos = episode_protocols(cfg, list(range(10)))
    groups = length_groups(protos)
    assert len(groups) == 2
    padded = simulate_sensors_padded(cfg, protos)
    for n, idx in groups:
        sens, target = simulate_sensors(cfg, [protos[i] for i in idx])
        ps, pt = padded[n]
        np.testing.assert_array_equal(pt, target)
        if exact:  # Warp's CPU device: the same float32 arithmetic per world whatever the batch
            np.testing.assert_array_equal(ps, sens)
        else:  # GPU atomics need not repeat bit for bit: within 0.1 % of full scale
            fmax = np.abs(sens[..., 4:7]).max()
            assert np.abs(ps[..., 4:7] - sens[..., 4:7]).max() < 1e-3 * fmax
            np.testing.assert_allclose(ps[..., 0:3], sens[..., 0:3], atol=1e-7)


@pytest.mark.skipif(not available(), reason="mujoco_warp not installed (extra: gpu)")
@pytest.mark.slow
def test_padded_worlds_equal_their_own_length_batches_cpu():
    _padded_equals_bucketed("cpu", exact=True)


@pytest.mark.gpu
def test_padded_worlds_equal_their_own_length_batches_gpu(gpu_device):
    _padded_equals_bucketed(gpu_device, exact=gpu_device == "cpu")

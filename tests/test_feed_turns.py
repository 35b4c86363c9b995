"""The GPU feed's physics processes step their batches' worlds in turns, in batch order (simulate/generation/feed.py,
`_gpu_turn`): a later batch waits for the earlier ones, a failed batch still hands the turn on, and a stopped feed
releases every waiter with an error instead of a hang."""

import os
import threading
import time

import pytest

from simulate.generation import feed


@pytest.fixture
def turns():
    path = feed.new_turns()
    yield path
    os.unlink(path)


def test_batches_step_in_batch_order_whatever_order_they_arrive(turns):
    order, inside, overlap = [], [0], []

    def batch(b: int) -> None:
        with feed._gpu_turn(turns, b):
            inside[0] += 1
            overlap.append(inside[0])
            order.append(b)
            time.sleep(0.02)
            inside[0] -= 1

    threads = [threading.Thread(target=batch, args=(b,)) for b in (3, 1, 2, 0)]  # the last batch asks first
    for t in threads:
        t.start()
        time.sleep(0.01)
    for t in threads:
        t.join(5)
    assert order == [0, 1, 2, 3]
    assert max(overlap) == 1  # one batch on the GPU at a time


def test_a_failed_batch_hands_its_turn_on(turns):
    with pytest.raises(ValueError):
        with feed._gpu_turn(turns, 0):
            raise ValueError("worlds failed")
    t0 = time.perf_counter()
    with feed._gpu_turn(turns, 1):
        pass
    assert time.perf_counter() - t0 < 1.0


def test_a_stopped_feed_releases_the_waiting_batches_with_an_error(turns):
    errors = []

    def waiter() -> None:
        try:
            with feed._gpu_turn(turns, 2):  # batches 0 and 1 never step
                errors.append(None)
        except RuntimeError as exc:
            errors.append(str(exc))

    t = threading.Thread(target=waiter)
    t.start()
    time.sleep(0.05)
    assert t.is_alive()  # waiting for batch 0 and 1
    feed.stop_turns(turns)
    t.join(2)
    assert not t.is_alive() and errors == ["the feed stopped before batch 2's turn on the GPU"]


def test_a_batch_stepping_when_the_feed_stops_does_not_undo_the_stop(turns):
    with feed._gpu_turn(turns, 0):
        feed.stop_turns(turns)
    assert feed._turn_update(turns, lambda now: None) == feed.TURN_ABORT
    with pytest.raises(RuntimeError, match="batch 1"):
        with feed._gpu_turn(turns, 1):
            pass

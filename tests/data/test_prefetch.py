import threading

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.data.batches import BatchStream
from dsfec_jax.data.points.pillarize import PillarSpec
from dsfec_jax.data.prefetch import BatchFailed, Prefetcher
from conftest import tiny
from builders import toy_frame

WAIT_S = 10  # a worker that should act within this long is broken (the tests never time anything)


def tiny_stream():
    det = tiny("dsfec_s")
    frames = [toy_frame(np.random.default_rng(i), det.config.grid) for i in range(6)]
    return BatchStream(frames, PillarSpec.of(det.config), zoo.family_of(det.config).points.targets(det.config),
                       batch_size=2, seed=7)


@pytest.mark.parametrize("depth", [1, 3])
def test_prefetched_batches_are_the_direct_ones_in_step_order(depth):
    stream = tiny_stream()
    with Prefetcher(stream.batch, range(2, 9), depth=depth) as batches:
        got = list(batches)
    assert [step for step, _ in got] == list(range(2, 9))
    for step, batch in got:
        direct = stream.batch(step)
        assert batch["window"] == direct["window"] and batch["stats"] == direct["stats"]
        jax.tree.map(np.testing.assert_array_equal, batch["inputs"], direct["inputs"])
        jax.tree.map(np.testing.assert_array_equal, batch["targets"], direct["targets"])
    different = stream.batch(3)["inputs"]["points"]
    assert not np.array_equal(got[0][1]["inputs"]["points"], different)  # the comparison can fail


def test_a_worker_error_is_raised_in_the_consumer_naming_its_step():
    def make(step):
        if step == 3:
            raise ValueError("no frames left")
        return step * 10

    received = []
    message = r"batch of step 3 failed in the prefetch worker: ValueError: no frames left"
    with pytest.raises(BatchFailed, match=message) as err:
        with Prefetcher(make, range(6)) as batches:
            for step, batch in batches:
                received.append((step, batch))
    assert received == [(0, 0), (1, 10), (2, 20)]
    assert err.value.step == 3 and isinstance(err.value.__cause__, ValueError)
    assert not batches.worker.is_alive()


def test_the_worker_builds_ahead_but_no_further_than_its_queue():
    built = {s: threading.Event() for s in range(8)}

    def make(step):
        built[step].set()
        return step

    with Prefetcher(make, range(8), depth=2) as batches:
        it = iter(batches)
        assert next(it) == (0, 0)
        # two queued (1, 2) and one built that waits for room (3) while the consumer holds step 0
        assert built[3].wait(WAIT_S)
        assert not built[4].wait(0.2)
        assert [s for s, _ in it] == list(range(1, 8))


def test_leaving_early_stops_the_worker():
    """A break, an exception (KeyboardInterrupt included) or a generator dropped mid-way: no live
    worker thread is left behind, even one blocked on a full queue."""
    def make(step):
        return np.zeros(4) + step

    with Prefetcher(make, range(1000), depth=1) as batches:
        for step, _ in batches:
            if step == 2:
                break
    assert not batches.worker.is_alive()

    with pytest.raises(KeyboardInterrupt):
        with Prefetcher(make, range(1000), depth=1) as batches:
            for step, _ in batches:
                raise KeyboardInterrupt
    assert not batches.worker.is_alive()

    batches = Prefetcher(make, range(1000), depth=1)
    it = iter(batches)
    next(it)
    it.close()  # what the garbage collector does with an abandoned generator
    assert not batches.worker.is_alive()
    assert not [t for t in threading.enumerate() if t.name == "batch-prefetch"]


def test_bad_depth_a_second_pass_and_a_closed_prefetcher_are_refused():
    with pytest.raises(ValueError, match=r"Prefetcher depth: expected an int >= 1 .* got 0"):
        Prefetcher(lambda s: s, range(3), depth=0)
    batches = Prefetcher(lambda s: s, range(3))
    assert list(batches) == [(0, 0), (1, 1), (2, 2)]
    with pytest.raises(RuntimeError, match="iterated once"):
        list(batches)
    assert not batches.worker.is_alive()
    with Prefetcher(lambda s: s, range(3)) as batches:
        pass
    with pytest.raises(RuntimeError, match="before it is closed"):  # rather than wait for a stopped worker
        list(batches)

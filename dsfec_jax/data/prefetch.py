"""Batches computed ahead of the training step by a background thread, yielded in step order.

While the train step runs (on XLA's threads, whether JAX dispatched it asynchronously or, as the
project's commands do, runs it inline on the main thread: core/host_memory.py), a worker thread
builds the next batches (augmentation, pillarization, targets) into a bounded queue. numpy
releases the GIL in its array kernels (https://numpy.org/doc/stable/reference/thread_safety.html),
and jaxlib releases it while XLA runs, so one Python thread is enough to overlap the two. The
worker shares the process's CPUs with XLA (core.threads pins every thread of the process), so on
a machine whose cores the step keeps busy it hides only what the step leaves idle.

The worker only calls `make(step)` for the steps asked for, in order: a batch stays whatever
`make` returns for its step (BatchStream.batch is a pure function of (seed, step)), so
prefetching changes when a batch is built, never what it holds.

    with Prefetcher(stream.batch, range(start, end)) as batches:
        for step, batch in batches:
            ...

Leaving the `with` block (normally, by an exception or a KeyboardInterrupt) stops the worker.
"""

from __future__ import annotations

import logging
import queue
import threading
from typing import Callable, Generic, Iterable, Iterator, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")

DEFAULT_DEPTH = 2   # batches built ahead: one to hand over at once, one being built meanwhile
POLL_S = 0.1        # how often a side waiting on the queue (full or empty) looks whether the other stopped
JOIN_S = 30.0       # how long close() waits for a batch being built to finish
_END = object()     # the worker's last item: every step was built


class BatchFailed(RuntimeError):
    """`make(step)` raised in the worker; the original exception is the cause (__cause__)."""

    def __init__(self, step: int, error: BaseException):
        super().__init__(f"building the batch of step {step} failed in the prefetch worker: "
                         f"{type(error).__name__}: {error}")
        self.step = step


class Prefetcher(Generic[T]):
    """(step, make(step)) for each of `steps` in order, built up to `depth` steps ahead by a daemon
    thread. Iterate it once, inside `with` (or call close()), so the worker always stops."""

    def __init__(self, make: Callable[[int], T], steps: Iterable[int], depth: int = DEFAULT_DEPTH,
                 name: str = "batch-prefetch"):
        if not isinstance(depth, int) or depth < 1:
            raise ValueError(f"Prefetcher depth: expected an int >= 1 (batches built ahead), got {depth!r}")
        self._make, self._steps = make, list(steps)
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._iterated = self._closed = False

    @property
    def worker(self) -> threading.Thread:
        return self._thread

    def __enter__(self) -> "Prefetcher[T]":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __iter__(self) -> Iterator[tuple[int, T]]:
        if self._iterated or self._closed:
            raise RuntimeError("a Prefetcher is iterated once, before it is closed; make a new one for another pass")
        self._iterated = True
        self._thread.start()
        try:
            while True:
                item = self._next_item()
                if item is _END:
                    return
                step, batch, error = item
                if error is not None:
                    raise BatchFailed(step, error) from error
                yield step, batch
        finally:
            self.close()

    def close(self) -> None:
        """Stop the worker and wait for it (it finishes the batch it is building, at most JOIN_S).
        Once only: an unfinished iterator closes it again when collected, maybe at interpreter exit."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._drain()
        if self._thread.is_alive():
            self._thread.join(JOIN_S)
            if self._thread.is_alive():  # a daemon: it cannot keep the process alive
                log.warning("%s: the worker is still building a batch after %.0f s; left behind",
                            self._thread.name, JOIN_S)

    def _next_item(self):
        """The worker's next item; RuntimeError if it stopped without one (closed meanwhile)."""
        while True:
            try:
                return self._queue.get(timeout=POLL_S)
            except queue.Empty:
                if not self._thread.is_alive() and self._queue.empty():
                    raise RuntimeError(f"{self._thread.name}: the worker stopped before its last step "
                                       "(the Prefetcher was closed while being iterated)") from None

    def _drain(self) -> None:
        """Free the queued batches (and a worker blocked on a full queue)."""
        while True:
            try:
                self._queue.get_nowait()
            except queue.Empty:
                return

    def _put(self, item) -> bool:
        """Queue `item`, waiting for room unless stopped -> whether it was queued."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def _work(self) -> None:
        for step in self._steps:
            if self._stop.is_set():
                return
            try:
                item = (step, self._make(step), None)
            except BaseException as error:  # handed to the consumer, which raises it naming the step
                self._put((step, None, error))
                return
            if not self._put(item):
                return
        self._put(_END)

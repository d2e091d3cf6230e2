"""CPU thread-count control: pin the whole process to N CPUs before XLA's CPU backend starts.

jaxlib 0.10 has no XLA flag for a thread count (`intra_op_parallelism_threads` is a TensorFlow
session option; in XLA_FLAGS it aborts start-up, and `--xla_cpu_multi_thread_eigen=false` still
runs work on the Eigen pool). The CPU client sizes its Eigen pool from the CPUs the process may
run on (sched_getaffinity), so N threads = every thread of the process pinned to N CPUs before
the first computation. The pin also caps any other pool (ONNX Runtime still gets its own count).
Measured: pinned to 1 CPU the pool has 1 `tf_XLAEigen` thread, to 2 CPUs it has 2.
No jax import here: this must run before XLA starts.
"""

from __future__ import annotations

import os
from pathlib import Path

EIGEN_THREAD = "tf_XLAEigen"  # name XLA gives its CPU intra-op pool threads (Linux /proc comm)
TASKS = Path("/proc/self/task")


def available_cpus() -> list[int]:
    """CPUs this process may run on (its affinity), or 0..cpu_count-1 where affinity is unknown."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(os.cpu_count() or 1))


def check(threads: int, cpus: list[int] | None = None) -> None:
    """A clear error for a thread count this process cannot honour."""
    cpus = available_cpus() if cpus is None else cpus
    if not hasattr(os, "sched_setaffinity"):
        raise RuntimeError(f"--threads {threads}: thread-count control needs Linux CPU affinity (os.sched_setaffinity)")
    if not 1 <= threads <= len(cpus):
        raise ValueError(f"--threads {threads}: expected 1..{len(cpus)} (the CPUs this process may use: {cpus})")


def eigen_threads() -> int | None:
    """Threads in XLA's CPU pool right now (0 before XLA starts); None where /proc is missing."""
    try:
        return sum((t / "comm").read_text().strip() == EIGEN_THREAD for t in TASKS.iterdir())
    except OSError:
        return None


def pin(threads: int, cpus: list[int] | None = None) -> list[int]:
    """Pin every thread of this process to the first `threads` allowed CPUs (or to `cpus`, a
    chosen set of allowed CPUs: a worker among several on one node) -> those CPUs. Threads XLA
    creates later inherit the pin, so it sizes its pool to `threads`."""
    allowed = available_cpus()
    if cpus is not None and (len(cpus) != threads or not set(cpus) <= set(allowed)):
        raise ValueError(f"pinning {threads} threads to CPUs {list(cpus)}; this process may use only {allowed}")
    check(threads, allowed)
    if eigen_threads():
        raise RuntimeError(f"--threads {threads}: XLA's CPU backend has already started with its own thread pool; "
                           "set the thread count before the first jax computation")
    chosen = list(cpus) if cpus is not None else allowed[:threads]
    for task in TASKS.iterdir():  # sched_setaffinity(0) pins only the calling thread
        try:
            os.sched_setaffinity(int(task.name), chosen)
        except ProcessLookupError:  # the thread ended meanwhile
            pass
    os.environ["OMP_NUM_THREADS"] = str(threads)
    return chosen

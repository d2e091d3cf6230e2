"""--threads in `dsfec bench` and `python -m dsfec_jax.profile`: a real thread count, recorded truthfully.

Each CLI runs in a subprocess (pinning is per process and XLA sizes its pool once). A
sitecustomize on PYTHONPATH (builders.TINY_MODEL_SITE) registers a tiny model (with an init
that compiles nothing) in every process, bench workers included, so the real entry points run
in seconds.
"""

import json
import os
import subprocess
import sys

import pytest

from dsfec_jax.core import threads
from builders import tiny_model_pythonpath


@pytest.fixture(autouse=True)
def two_cpus():
    """The issue asks for 2 threads to be tested, so a machine that cannot give them fails, not skips
    (CI runs on the project's 2-core Linux machines)."""
    if not hasattr(os, "sched_setaffinity") or len(threads.available_cpus()) < 2:
        pytest.fail(f"--threads 2 needs Linux CPU affinity and 2 CPUs; this process may use {threads.available_cpus()}")


def run_cli(tmp_path, args: list[str]) -> subprocess.CompletedProcess:
    # XLA_FLAGS stays: the session's compile-cheaply flag (conftest) reaches the CLI and its bench
    # workers, which compile their programs faster; it does not touch the thread pools
    env = {**os.environ, "PYTHONPATH": tiny_model_pythonpath(tmp_path)}
    proc = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def test_bench_threads_1_and_2_pin_each_worker_and_record_xla_pool(tmp_path):
    proc = run_cli(tmp_path, ["-m", "dsfec_jax.cli", "bench", "--models", "tiny_s", "--runtimes", "jax",
                              "--threads", "1,2", "--repeats", "1", "--warmup", "0", "--json"])
    records = json.loads(proc.stdout)
    assert [r["threads"] for r in records] == [1, 2]
    # the evidence: XLA's Eigen pool as observed in the worker, and the CPUs the worker could use
    assert [r["xla_threads"] for r in records] == [1, 2]
    assert [len(r["cpu_affinity"]) for r in records] == [1, 2]


@pytest.mark.parametrize("count", [1, 2])  # both, so an unpinned run (all CPUs) cannot pass
def test_profile_threads_pins_the_process(tmp_path, count):
    proc = run_cli(tmp_path, ["-m", "dsfec_jax.profile", "--models", "tiny_s", "--threads", str(count),
                              "--repeats", "1", "--warmup", "0", "--json"])
    setup = json.loads(proc.stdout)[0]["latency_setup"]
    assert setup["threads"] == count and len(setup["cpu_affinity"]) == count  # XLA's pool, observed


def test_a_thread_count_beyond_the_cpus_is_refused_by_name():
    with pytest.raises(ValueError, match=r"--threads 3: expected 1\.\.2"):
        threads.check(3, [0, 1])
    with pytest.raises(ValueError, match="--threads 0"):
        threads.check(0, [0, 1])

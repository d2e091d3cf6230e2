"""One worker process per thread count, and `run`, which launches them and gathers their records.
A worker times the chains each model's modality builds (`Modality.bench_chains`: runtime -> (chain,
record fields)); its entry point (`python -m dsfec_jax.deploy.bench`, __main__.py) looks the
modality up and passes `chains_of(model name) -> that verb` in.

XLA has no thread-count flag and sizes its pool from the CPUs it may use when it starts, so each
--threads value N runs in its own worker process (`python -m dsfec_jax.deploy.bench`) pinned to N
CPUs before XLA starts (core/threads.py); ONNX Runtime gets intra_op_num_threads=N. Within a worker
every (model, runtime) chain is timed in one interleaved loop (timing.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np

from ...core import threads as thread_control
from .timing import time_chains


def worker(models: list[str], runtimes: list[str], threads: int, repeats: int, warmup: int,
           chains_of: Callable[[str], Callable[..., dict]]) -> list[dict]:
    """One process, one thread count: every (model, runtime) chain timed in one interleaved loop.
    `chains_of(name)` -> the model's `bench_chains(name, runtimes, threads, workdir, repeats)`."""
    from ...core.environment import cpu_model, xla_threads
    from ...core.provenance import versions

    chains, extra = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in models:
            for rt, (steps, fields) in chains_of(name)(name, runtimes, threads, Path(tmp), repeats).items():
                chains[(name, rt)], extra[(name, rt)] = steps, fields
        samples = time_chains(chains, repeats, warmup)
    # threads: the count asked for; xla_threads: XLA's pool as observed after the runs (the truth)
    env = {"cpu": cpu_model(), "threads": threads, "xla_threads": xla_threads(),
           "cpu_affinity": thread_control.available_cpus(), "versions": versions(
        ("jax", "jaxlib", "flax", "numpy", "onnxruntime", "jax2onnx", "dsfec_jax"))}
    records = []
    for (name, rt), s in samples.items():
        med = {k: round(float(np.median(v)), 3) for k, v in s.items()}
        records.append({"model": name, "runtime": rt, "threads": threads,
                        "stages_ms": {k: med[k] for k in s if k != "total"}, "total_ms": med["total"],
                        "total_p90_ms": round(float(np.percentile(s["total"], 90)), 3),
                        "fps_batch1": round(1e3 / med["total"], 2), "repeats": repeats, "warmup": warmup,
                        **extra[(name, rt)], **env})
    return records


def run(models: list[str], runtimes: list[str], threads: list[int], repeats: int = 20, warmup: int = 3) -> list[dict]:
    """Each thread count in a worker process pinned to that many CPUs (XLA's pool is fixed at
    start-up) -> all records."""
    for t in threads:  # refuse a count the machine cannot give before any worker starts
        thread_control.check(t)
    records = []
    for t in threads:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "records.json"
            cmd = [sys.executable, "-m", "dsfec_jax.deploy.bench", "--models", ",".join(models),
                   "--runtimes", ",".join(runtimes), "--threads", str(t), "--repeats", str(repeats),
                   "--warmup", str(warmup), "--records-out", str(out)]
            env = {**os.environ, "OMP_NUM_THREADS": str(t)}
            proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"bench worker (threads={t}) failed:\n{proc.stderr[-3000:]}")
            records += json.loads(out.read_text())
    return records


def main(chains_of: Callable[[str], Callable[..., dict]], argv=None) -> int:
    """The worker (__main__.py passes `chains_of`, see `worker`); users run `dsfec bench`."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m dsfec_jax.deploy.bench")
    p.add_argument("--models", required=True)
    p.add_argument("--runtimes", required=True)
    p.add_argument("--threads", type=int, required=True)
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--records-out", required=True)
    a = p.parse_args(argv)
    thread_control.pin(a.threads)  # before the first jax computation: XLA sizes its pool from it
    records = worker(a.models.split(","), a.runtimes.split(","), a.threads, a.repeats, a.warmup, chains_of)
    Path(a.records_out).write_text(json.dumps(records))
    return 0

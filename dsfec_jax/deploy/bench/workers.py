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
import logging
import os
import sys
import tempfile
from pathlib import Path
from typing import Callable

from ...core import machine_load, progress, spread
from ...core.child_process import run_passing_stderr
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
            with progress.stage(f"preparing {name} for {', '.join(runtimes)} (weights, ONNX export, INT8 "
                                "calibration, JAX throughput)"):
                built = chains_of(name)(name, runtimes, threads, Path(tmp), repeats)
            for rt, (steps, fields) in built.items():
                chains[(name, rt)], extra[(name, rt)] = steps, fields
        with machine_load.watch() as load:  # the machine around the timed loop: busy or not
            samples = time_chains(chains, repeats, warmup)
    machine_load.warn(load.verdict, f"the bench's timing ({threads} thread{'s' * (threads > 1)})")
    # threads: the count asked for; xla_threads: XLA's pool as observed after the runs (the truth)
    env = {"cpu": cpu_model(), "threads": threads, "xla_threads": xla_threads(),
           "cpu_affinity": thread_control.available_cpus(), "versions": versions(
        ("jax", "jaxlib", "flax", "numpy", "onnxruntime", "jax2onnx", "dsfec_jax"))}
    records = []
    for (name, rt), s in samples.items():
        stats = {k: spread.percentiles(v) for k, v in s.items()}
        stages = [k for k in s if k != "total"]
        records.append({"model": name, "runtime": rt, "threads": threads,
                        "stages_ms": {k: stats[k]["median"] for k in stages},
                        "stages_p10_p90_ms": {k: [stats[k]["p10"], stats[k]["p90"]] for k in stages},
                        "total_ms": stats["total"]["median"], "total_p10_ms": stats["total"]["p10"],
                        "total_p90_ms": stats["total"]["p90"],
                        "fps_batch1": round(1e3 / stats["total"]["median"], 2), "repeats": repeats, "warmup": warmup,
                        "machine": load.verdict, **extra[(name, rt)], **env})
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
            code, tail = run_passing_stderr(cmd, env)  # the worker's progress reaches the user
            if code != 0:
                raise RuntimeError(f"bench worker (threads={t}) failed:\n{tail}")
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
    # the worker's stderr now reaches the user: keep it to progress and errors. onnx_ir warns once per
    # graph value whose type the exporter leaves unset (the decode graph's top-k outputs); the graphs
    # run and agree with JAX (tests/deploy), so the dozen lines per model say nothing to act on
    logging.getLogger("onnx_ir").setLevel(logging.ERROR)
    thread_control.pin(a.threads)  # before the first jax computation: XLA sizes its pool from it
    records = worker(a.models.split(","), a.runtimes.split(","), a.threads, a.repeats, a.warmup, chains_of)
    Path(a.records_out).write_text(json.dumps(records))
    return 0

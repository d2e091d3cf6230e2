"""Checkpoint write time, A/B: the msgpack save the loop used (core/checkpoint.save of the state
brought to the host) against Orbax's (core/run_checkpoints.RunCheckpoints.save), on the whole
training state of real detectors (parameters, BN statistics, optimizer state, step), interleaved
in one process (msgpack, Orbax, msgpack, Orbax, ...). For Orbax it times both what the training
loop waits for (`save` returns once the arrays are on the host) and the whole write (until the
step is renamed into place). Prints per model the state's size and, per form, the median and the
min-max over the rounds, in ms.

    python -m experiments.checkpoint_write --models yolov8n,dsfec_l --rounds 9 --dir runs/ckpt_bench
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import json
import shutil
import statistics
import tempfile
import time
from pathlib import Path


def training_state(name: str):
    import jax

    from dsfec_jax import zoo
    from dsfec_jax.train.schedules import get_schedule, optimizer
    from dsfec_jax.train.step import init_state

    det = zoo.create(name)
    return jax.block_until_ready(init_state(det, optimizer(get_schedule("quick"), 1000), jax.random.key(0)))


def time_msgpack(state, directory: Path, step: int) -> dict:
    import jax

    from dsfec_jax.core import checkpoint

    t0 = time.perf_counter()
    checkpoint.save(directory / f"step_{step:07d}.msgpack", jax.device_get(state), {"step": step})
    return {"msgpack_ms": 1e3 * (time.perf_counter() - t0)}


def time_orbax(run, state, step: int) -> dict:
    t0 = time.perf_counter()
    run.save(step, state, {"loss": 0.0})
    blocked = time.perf_counter() - t0
    run.last.wait_until_finished()
    return {"orbax_blocked_ms": 1e3 * blocked, "orbax_total_ms": 1e3 * (time.perf_counter() - t0)}


def summary(values: list[float]) -> dict:
    return {"median": round(statistics.median(values), 1), "min": round(min(values), 1), "max": round(max(values), 1)}


def measure(name: str, rounds: int, root: Path) -> dict:
    import jax
    import numpy as np

    from dsfec_jax.core.run_checkpoints import RunCheckpoints

    state = training_state(name)
    directory = Path(tempfile.mkdtemp(prefix=f"{name}_", dir=root))
    times: dict[str, list[float]] = {}
    with RunCheckpoints(directory / "orbax", keep=2) as run:
        time_orbax(run, state, 0)  # the first save builds Orbax's handlers: not a round
        for r in range(1, rounds + 1):
            for result in (time_msgpack(state, directory, r), time_orbax(run, state, r)):
                for k, v in result.items():
                    times.setdefault(k, []).append(v)
    shutil.rmtree(directory)
    size = sum(np.asarray(x).nbytes for x in jax.tree.leaves(state))
    return {"model": name, "state_mb": round(size / 2**20, 1), "rounds": rounds,
            **{k: summary(v) for k, v in times.items()}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", default="yolov8n,dsfec_l")
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--dir", default=".", help="where the checkpoints are written (removed after)")
    args = p.parse_args(argv)
    root = Path(args.dir)
    root.mkdir(parents=True, exist_ok=True)
    for name in args.models.split(","):
        print(json.dumps(measure(name, args.rounds, root)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

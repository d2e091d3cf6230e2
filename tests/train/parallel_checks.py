"""The checks of tests/train/test_parallel.py that need more than the test runner's one CPU device.
Run as a child process (JAX fixes its device count when it starts):

    python tests/train/parallel_checks.py devices RESULT.json          # 2 forced host devices
    python tests/train/parallel_checks.py process I PORT RUN_DIR RESULT.json   # one of 2 processes

Each mode writes a JSON of what it measured; the test asserts on it (the assertions stay in the test
file, so a failure names the number that moved).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import jax

from dsfec_jax import cli
from dsfec_jax.train import parallel
from dsfec_jax.train.schedules import get_schedule

TESTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(TESTS))

STEPS = 2  # steps each family's one-device and sharded step are compared over
BATCH = 2  # the global batch: one row per device
TOTAL = 3  # steps of the runs through train.loop
ROWS_BUILT: set[int] = set()  # the rows counts the runs' batches were built with
# Plain SGD with momentum (darknet's): an update proportional to the gradient, so parameters agree
# as closely as the gradients do. Adam would not show it: a gradient that is zero in exact
# arithmetic (a bias ahead of BatchNorm) is float noise of either sign, and Adam scales any
# such noise up to a full learning-rate step.
SCHEDULE = get_schedule("quick", learning_rate=1e-4, warmup_steps=1, batch_size=BATCH, optimizer="darknet",
                        weight_decay=0.0)
# family -> (a variant, overrides) that compile in seconds (tests/modalities/test_contract.py's TINY)
MODELS = {
    "dsfec": ("dsfec_s", {"stage_blocks": (1, 1, 1, 1), "head_convs": 1}),
    "radarnext": ("radarnext_fpn", {"layer_nums": (1, 1, 1)}),
    "yolo_rd": ("yolov8n", {}),
    "camera": ("shuffle_yolov3", {"widths": (16, 16, 32, 32, 64), "repeats": (1, 1, 1, 1, 1),
                                  "head_widths": (16, 32, 64), "head_units": 1, "num_classes": 5,
                                  "class_names": ("car", "truck", "bus", "pedestrian", "cyclist")}),
}


def tiny_points(overrides: dict) -> dict:
    from conftest import TINY_GRID

    return {"grid": TINY_GRID, "max_pillars": 96, "max_points": 4, **overrides}


def family_batch(name: str, overrides: dict):
    """(detector, one global batch {'inputs', 'targets'} as the family's training stream makes it)."""
    from dsfec_jax import zoo
    from dsfec_jax.modalities.registry import modality_of
    from dsfec_jax.profile.training import Settings

    cfg = zoo.config(name, **overrides)
    settings = Settings(batch=BATCH, window=None, max_pillars=96, distinct_batches=1, budget_frames=BATCH,
                        image_size=64, size_pillars=False)
    det, batches, _ = modality_of(cfg).train_bench_batches(name, overrides, settings)
    return det, jax.device_get(batches[0])


def fresh_state(det, tx):
    """A training state without compiling init: random weights and BN statistics of init's shapes."""
    import jax.numpy as jnp
    from conftest import random_variables

    variables = random_variables(det, 0)
    return {"params": variables["params"], "batch_stats": variables.get("batch_stats", {}),
            "opt_state": tx.init(variables["params"]), "step": jnp.zeros((), jnp.int32)}


def max_difference(a, b) -> float:
    import numpy as np

    return max(float(np.max(np.abs(np.asarray(x, np.float64) - np.asarray(y, np.float64)), initial=0.0))
               for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def compare_steps(family: str) -> dict:
    """One-device and 2-device steps from the same state on the same global batch, STEPS times."""
    from dsfec_jax.train.schedules import optimizer
    from dsfec_jax.train.step import make_train_step

    name, overrides = MODELS[family]
    if family == "dsfec":  # run_points's network, batch and step: its runs find these programs in the cache
        det = points_detector()
        batch = {k: points_stream(det).batch(0)[k] for k in ("inputs", "targets")}
    else:
        det, batch = family_batch(name, tiny_points(overrides) if family == "radarnext" else overrides)
    tx = optimizer(SCHEDULE, TOTAL)
    one, two = parallel.layout(1), parallel.layout(2)
    steps = {n: lay.step(make_train_step(det, tx)) for n, lay in ((1, one), (2, two))}
    states = {1: fresh_state(det, tx), 2: two.replicate(fresh_state(det, tx))}
    losses = {1: [], 2: []}
    for _ in range(STEPS):
        for n, lay in ((1, one), (2, two)):
            states[n], metrics = steps[n](states[n], lay.batch_on_devices(batch))
            losses[n].append(float(metrics["loss"]))
    rows = jax.tree.leaves(batch)[0].shape[0]
    sharded = all(len(a.sharding.device_set) == 2 and a.sharding.spec[0] == parallel.DATA_AXIS
                  for a in jax.tree.leaves(two.batch_on_devices(batch)["inputs"]))
    replicated = all(a.sharding.is_fully_replicated and len(a.sharding.device_set) == 2
                     for a in jax.tree.leaves(states[2]))
    host = jax.device_get(states)
    return {"losses_1": losses[1], "losses_2": losses[2], "rows": rows, "batch_sharded": sharded,
            "state_replicated": replicated,
            "params": max_difference(host[1]["params"], host[2]["params"]),
            "batch_stats": max_difference(host[1]["batch_stats"], host[2]["batch_stats"]),
            "params_moved": max_difference(host[1]["params"], fresh_state(det, tx)["params"])}


def points_detector():
    from conftest import tiny

    name, overrides = MODELS["dsfec"]
    return tiny(name, **overrides)


def points_stream(det):
    from builders import toy_frame
    from dsfec_jax import zoo
    from dsfec_jax.data.batches import BatchStream
    from dsfec_jax.data.points.pillarize import PillarSpec
    import numpy as np

    class RowsCounted(BatchStream):  # the rows each batch built (ROWS_BUILT): a process builds its own only
        def batch(self, step, rows=slice(None)):
            ROWS_BUILT.add(len(range(self.batch_size)[rows]))
            return super().batch(step, rows)

    frames = [toy_frame(np.random.default_rng(i), det.config.grid) for i in range(4)]
    return RowsCounted(frames, PillarSpec.of(det.config), zoo.family_of(det.config).points.targets(det.config),
                       batch_size=BATCH, seed=7)


def run_points(run_dir: Path, devices: int, stop_at: int | None = None) -> dict:
    """train.loop.train of the tiny DSFEC on `devices` devices (the launch's --devices)."""
    from dsfec_jax.train.loop import RunSpec, train

    parallel.use_devices(devices)  # what `--devices N` sets at start
    spec = RunSpec(run_dir, SCHEDULE, seed=0, total_steps=TOTAL, stop_at=stop_at, log_every=1, ckpt_every=100,
                   progress=False)
    det = points_detector()
    return train(det, points_stream(det), spec, {"test": True})[0]


def metric_losses(run_dir: Path) -> list[float]:
    rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [r["loss"] for r in rows if "loss" in r]


def resume_checks(tmp: Path) -> dict:
    """A sharded run stopped and resumed on 2 devices, and one resumed on 1 device, against the
    straight sharded run; and a batch that does not divide."""
    straight = jax.device_get(run_points(tmp / "straight", 2))
    run_points(tmp / "resumed", 2, stop_at=1)
    resumed = jax.device_get(run_points(tmp / "resumed", 2))
    run_points(tmp / "moved", 2, stop_at=1)
    moved = jax.device_get(run_points(tmp / "moved", 1))
    record = json.loads((tmp / "moved" / "run.json").read_text())
    refused = ""
    try:  # the command refuses before it loads any data
        cli.main(["train", "--model", "yolov8n", "--devices", "2", "--batch-size", "3", "--run-dir", str(tmp / "odd")])
    except SystemExit as exit:
        refused = str(exit.code)
    return {"resumed": max_difference(straight["params"], resumed["params"]),
            "moved": max_difference(straight["params"], moved["params"]),
            "losses": {n: metric_losses(tmp / n) for n in ("straight", "resumed", "moved")},
            "step": [int(straight["step"]), int(resumed["step"]), int(moved["step"])],
            "parallel": record["parallel"], "resume_parallel": record["resumes"][0]["parallel"],
            "refused": refused}


def per_step_checks() -> dict:
    """A batch whose rows are split and whose per-step input (a supernet's subnet mask) is whole:
    where each lands on the mesh, and what a step on it computes against numpy."""
    import numpy as np

    lay = parallel.layout()
    rows, mask = np.arange(6, dtype=np.float32).reshape(2, 3), np.array([1.0, 0.0, 2.0], np.float32)
    placed = lay.batch_on_devices({"inputs": {"x": rows, "masks": {"m": mask}}, "targets": {"t": rows[:, 0]},
                                   parallel.PER_STEP_INPUTS: ("masks",)})
    step = lay.step(lambda state, b: (state + (b["inputs"]["x"] @ b["inputs"]["masks"]["m"]).sum(), state))
    state = jax.device_put(np.float32(1.0), lay.replicated)
    got, _ = step(state, {"inputs": placed["inputs"], "targets": placed["targets"]})
    return {"rows_sharded": placed["inputs"]["x"].sharding.spec == lay.batch_sharding.spec,
            "mask_replicated": placed["inputs"]["masks"]["m"].sharding.is_fully_replicated,
            "mask_shape": list(placed["inputs"]["masks"]["m"].shape),
            "step": float(got), "numpy": float(1.0 + (rows @ mask).sum())}


def devices_mode(result: Path) -> None:
    parallel.start(parallel.Launch(devices=2))
    t0 = time.perf_counter()
    out = {}
    for family in MODELS:
        out[family] = compare_steps(family)
        print(f"{family}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    out["resume"] = resume_checks(result.parent)
    out["per_step"] = per_step_checks()
    out["seconds"] = time.perf_counter() - t0
    result.write_text(json.dumps(out))


def process_mode(index: int, port: int, run_dir: Path, result: Path) -> None:
    """One of two processes on localhost, one CPU device each: the run's mesh is 2 devices."""

    parallel.start(parallel.Launch(devices=1, coordinator=f"127.0.0.1:{port}", num_processes=2, process_id=index))
    state = run_points(run_dir, 1)
    result.write_text(json.dumps({"process": jax.process_index(), "processes": jax.process_count(),
                                  "devices": len(state["step"].sharding.device_set), "step": int(state["step"]),
                                  "rows_built": sorted(ROWS_BUILT)}))


def main(argv: list[str]) -> None:
    # the suite's persistent cache (tests/conftest.py): the runs through the loop compile the
    # steps the comparison compiled once more, and a rerun compiles nothing
    cache = os.environ.get("DSFEC_TEST_COMPILATION_CACHE") or tempfile.mkdtemp(prefix="dsfec-parallel-cache-")
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    if argv[0] == "devices":
        devices_mode(Path(argv[1]))
    else:
        process_mode(int(argv[1]), int(argv[2]), Path(argv[3]), Path(argv[4]))


if __name__ == "__main__":
    main(sys.argv[1:])

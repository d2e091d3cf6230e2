"""Data-parallel training (dsfec_jax.train.parallel). The test runner's JAX has one CPU device, so
the checks on two devices run in child processes (tests/train/parallel_checks.py): one with two
host devices, and two processes on localhost joined by jax.distributed with the CPU collectives."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from dsfec_jax.train import parallel
from dsfec_jax.core.run_checkpoints import last_steps, read_state

CHECKS = Path(__file__).with_name("parallel_checks.py")
ROOT = Path(__file__).resolve().parents[2]
CHILD_S = 600  # a child that hangs (a collective waiting on a dead peer) fails the test, not the suite
FAMILIES = ("dsfec", "radarnext", "yolo_rd", "camera")


def child_env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
            "JAX_PLATFORMS": "cpu"}


@pytest.fixture(scope="module")
def two_devices(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("parallel") / "devices.json"
    done = subprocess.run([sys.executable, str(CHECKS), "devices", str(out)], env=child_env(), timeout=CHILD_S,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    return {**json.loads(out.read_text()), "dir": out.parent}


@pytest.mark.parametrize("family", FAMILIES)
def test_the_sharded_step_is_the_one_device_step_on_the_global_batch(two_devices, family):
    """Losses, parameters and BatchNorm statistics (computed over the global batch, as one device
    would) agree to float tolerance, with the batch split over both devices and the state replicated."""
    got = two_devices[family]
    assert got["rows"] == 2 and got["batch_sharded"] and got["state_replicated"]
    np.testing.assert_allclose(got["losses_2"], got["losses_1"], rtol=1e-5)
    # float32 on a toy batch: few occupied pillars leave BatchNorm nearly degenerate, which turns
    # rounding into differences of up to ~1e-3 between two summation orders (conftest.py's float64)
    assert got["params"] < 1e-3 and got["batch_stats"] < 1e-4, got
    assert got["params_moved"] > 10 * got["params"]  # the steps trained: agreement is not two untouched states


def test_a_sharded_run_resumes_exactly_and_on_another_device_count(two_devices):
    got = two_devices["resume"]
    assert got["step"] == [3, 3, 3]
    assert got["resumed"] == 0.0 and got["losses"]["resumed"] == got["losses"]["straight"]
    assert got["moved"] < 1e-5  # resumed on 1 device: the same global batch, another summation order
    np.testing.assert_allclose(got["losses"]["moved"], got["losses"]["straight"], rtol=1e-5)
    assert got["parallel"] == {"devices": 2, "processes": 1, "platform": "cpu", "mesh": {"axes": ["data"], "shape": [2]}}
    assert got["resume_parallel"]["devices"] == 1


def test_per_step_inputs_are_whole_on_every_device_and_rows_split(two_devices):
    got = two_devices["per_step"]
    assert got["rows_sharded"] and got["mask_replicated"] and got["mask_shape"] == [3]
    assert got["step"] == got["numpy"]


def test_a_batch_that_does_not_divide_is_refused_by_name(two_devices):
    message = two_devices["resume"]["refused"]
    assert "--batch-size 3" in message and "2 devices" in message, message


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_train_as_one_and_only_process_0_writes(two_devices, tmp_path):
    port = free_port()
    # one run directory, as on a shared filesystem: Orbax writes the checkpoints collectively there
    run = tmp_path / "run"
    children = [subprocess.Popen([sys.executable, str(CHECKS), "process", str(i), str(port), str(run),
                                  str(tmp_path / f"process{i}.json")], env=child_env(),
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for i in range(2)]
    try:
        errors = [child.communicate(timeout=CHILD_S)[1] for child in children]
    finally:
        for child in children:
            child.kill()
    assert [c.returncode for c in children] == [0, 0], [e[-3000:] for e in errors]
    results = [json.loads((tmp_path / f"process{i}.json").read_text()) for i in range(2)]
    assert [(r["process"], r["processes"], r["devices"], r["step"]) for r in results] == [(0, 2, 2, 3), (1, 2, 2, 3)]
    assert [r["rows_built"] for r in results] == [[1], [1]]  # each built its own row of the global batch of 2
    straight = two_devices["dir"] / "straight"
    assert json.loads((run / "run.json").read_text())["parallel"]["processes"] == 2
    # process 1 wrote none of the run's files: one row a step (the straight run's), one event file
    losses = [json.loads(l)["loss"] for l in (run / "metrics.jsonl").read_text().splitlines()]
    assert len(list(run.glob("events.out.tfevents.*"))) == 1
    np.testing.assert_allclose(losses, two_devices["resume"]["losses"]["straight"], rtol=1e-5)
    ours, theirs = (read_state(last_steps(r)[-1])["params"] for r in (run, straight))
    assert max(np.max(np.abs(a - b)) for a, b in zip(jax.tree.leaves(ours), jax.tree.leaves(theirs))) < 1e-5


def test_flags_that_do_not_fit_are_refused_by_name():
    cases = {parallel.Launch(devices=0): "--devices 0",
             parallel.Launch(num_processes=2): "need --coordinator",
             parallel.Launch(coordinator="localhost"): "expected HOST:PORT",
             parallel.Launch(coordinator="127.0.0.1:1234", num_processes=2): "--num-processes N and --process-id I",
             parallel.Launch(coordinator="127.0.0.1:1234", num_processes=2, process_id=2): "--process-id 2"}
    for launch, message in cases.items():
        with pytest.raises(parallel.ParallelError, match=message):
            parallel.start(launch)
    with pytest.raises(parallel.ParallelError, match="--devices 4: this process has 1 cpu device"):
        parallel.layout(4)
    assert parallel.layout().single and parallel.is_writer()

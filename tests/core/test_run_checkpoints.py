"""core.run_checkpoints: Orbax's managers for a run's last-N and best states. A kill -9 while an
asynchronous save writes leaves the previous checkpoint to resume from, keep-N and the best hold
apart, the loop may donate a state as soon as its save returns, and a run directory of msgpack
checkpoints is converted on its first resume."""

import os
import socket
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from dsfec_jax.core import checkpoint
from dsfec_jax.core.run_checkpoints import (LEGACY_DIR, RunCheckpoints, best_step, last_steps, read_extra,
                                            read_state)

ROOT = Path(__file__).resolve().parents[2]


def state(value: float, big: int = 4) -> dict:
    return {"params": {"w": jnp.full((big, 4), value, jnp.float32)}, "opt_state": (jnp.zeros(3), {}),
            "batch_stats": {}, "step": jnp.int32(value)}


# step 1 completes; step 2 (64 MB) is killed once its temporary directory is there, while the
# writing goes on in the background (exit 3: the save finished before the kill could land)
KILLED_WHILE_SAVING = """
import os, signal, sys, time
from pathlib import Path
from dsfec_jax.core.run_checkpoints import RunCheckpoints
from tests.core.test_run_checkpoints import state
run = RunCheckpoints(sys.argv[1], keep=2)
run.save(1, state(1.0), {"loss": 1.0})
run.save_best(1, state(1.0), 50.0, {})
run.last.wait_until_finished(); run.best.wait_until_finished()
run.save(2, state(2.0, big=1 << 22), {"loss": 2.0})
last, deadline = Path(sys.argv[1]) / "checkpoints" / "last", time.monotonic() + 30
while not list(last.glob("step_0000002.*tmp*")):
    if (last / "step_0000002").exists() or time.monotonic() > deadline:
        sys.exit(3)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_kill_during_an_async_save_resumes_from_the_step_before(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    done = subprocess.run([sys.executable, "-c", KILLED_WHILE_SAVING, str(tmp_path)], env=env, capture_output=True)
    assert done.returncode == -9, done.stderr.decode()[-2000:]
    torn = [p.name for p in (tmp_path / "checkpoints" / "last").iterdir() if "tmp" in p.name]
    assert torn and torn[0].startswith("step_0000002."), torn  # the kill did land mid-write
    assert [p.name for p in last_steps(tmp_path)] == ["step_0000001"]
    run = RunCheckpoints(tmp_path, keep=2)
    restored = run.restore(state(0.0))
    np.testing.assert_array_equal(restored["params"]["w"], np.ones((4, 4), np.float32))
    assert isinstance(restored["opt_state"], tuple) and int(restored["step"]) == 1
    assert run.best_score() == 50.0
    run.save(3, state(3.0), {"loss": 3.0})  # a resumed run saving elsewhere (another --ckpt-every)
    run.close()
    assert sorted(p.name for p in (tmp_path / "checkpoints" / "last").iterdir()) == ["step_0000001", "step_0000003"]


def test_keep_n_holds_and_the_best_is_kept_apart(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path.parent)  # a run directory given relative (--run-dir runs/x)
    with RunCheckpoints(tmp_path.name, keep=2, best_key="mAP") as run:
        for step in range(1, 6):
            run.save(step, state(float(step)), {"loss": float(step)})
            if step in (1, 3):
                run.save_best(step, state(float(step)), 10.0 * step, {"eval": {"mAP": 10.0 * step}})
        assert run.latest().name == "step_0000005"
        assert run.best_score() == 30.0
    assert [p.name for p in last_steps(tmp_path)] == ["step_0000004", "step_0000005"]
    best = best_step(tmp_path)
    assert best.name == "step_0000003" and read_extra(best) == {"step": 3, "mAP": 30.0, "eval": {"mAP": 30.0}}
    assert read_state(f"{tmp_path.name}/checkpoints/best")["params"]["w"][0, 0] == 3.0  # the manager dir reads its step


def test_the_saved_state_is_the_one_at_save_time_though_the_next_step_donates_it(tmp_path):
    """save returns once the arrays are on the host: the train step (donate_argnums=0) may reuse
    the buffers while the files are written."""
    step = jax.jit(lambda s: jax.tree.map(lambda x: x + 1, s), donate_argnums=0)
    live, expected = state(1.0, big=1 << 18), jax.tree.map(np.array, state(1.0, big=1 << 18))
    with RunCheckpoints(tmp_path) as run:
        run.save(1, live, {})
        for _ in range(3):
            live = step(live)
    jax.tree.map(np.testing.assert_array_equal, read_state(last_steps(tmp_path)[-1])["params"], expected["params"])
    assert float(live["params"]["w"][0, 0]) == 4.0


def test_a_msgpack_run_directory_is_converted_on_its_first_resume(tmp_path, caplog):
    """The newest complete msgpack checkpoint (one killed before its manifest is skipped) and
    best.msgpack become Orbax checkpoints; the msgpack files move aside, none is lost."""
    old = tmp_path / "checkpoints"
    host = lambda v: jax.tree.map(np.asarray, state(v))  # noqa: E731
    checkpoint.save(old / "step_0000002.msgpack", host(2.0), {"step": 2, "loss": 0.5})
    checkpoint.save(old / "step_0000004.msgpack", host(4.0), {"step": 4, "loss": 0.4})
    checkpoint.manifest_path(old / "step_0000004.msgpack").unlink()  # killed while saving
    checkpoint.save(old / "best.msgpack", host(2.0), {"step": 2, "car_mAP": 12.5, "eval": {"car_mAP": 12.5}})
    with RunCheckpoints(tmp_path) as run:
        restored = run.restore(state(0.0))
        assert int(restored["step"]) == 2 and isinstance(restored["opt_state"], tuple)
        assert run.best_score() == 12.5
    assert "converting the msgpack checkpoint step_0000002.msgpack" in caplog.text
    assert [p.name for p in last_steps(tmp_path)] == ["step_0000002"]
    assert read_extra(last_steps(tmp_path)[-1]) == {"step": 2, "loss": 0.5}
    assert read_extra(best_step(tmp_path)) == {"step": 2, "car_mAP": 12.5, "eval": {"car_mAP": 12.5}}
    assert not list(old.glob("*.msgpack*"))
    assert sorted(p.name for p in (old / LEGACY_DIR).iterdir()) == [
        "best.msgpack", "best.msgpack.json", "step_0000002.msgpack", "step_0000002.msgpack.json", "step_0000004.msgpack"]


# one of two jax.distributed processes (CPU, gloo collectives), each with one device of a 2-device
# mesh: both make every call, Orbax writes the replicated state once
TWO_PROCESSES = """
import sys
import jax
jax.config.update("jax_cpu_collectives_implementation", "gloo")
jax.distributed.initialize(f"127.0.0.1:{sys.argv[2]}", num_processes=2, process_id=int(sys.argv[1]))
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from dsfec_jax.core.run_checkpoints import RunCheckpoints
replicated = NamedSharding(Mesh(np.array(jax.devices()), ("data",)), PartitionSpec())
def state(v):
    w = jax.make_array_from_callback((4, 4), replicated, lambda i: np.full((4, 4), v, np.float32)[i])
    return {"params": {"w": w}, "step": jax.make_array_from_callback((), replicated, lambda i: np.int32(v))}
with RunCheckpoints(sys.argv[3], keep=2) as run:
    for step in (1, 2, 3):
        run.save(step, state(float(step)), {"loss": float(step)})
    run.save_best(2, state(2.0), 7.0, {})
with RunCheckpoints(sys.argv[3], keep=2) as run:
    w = run.restore(state(0.0))["params"]["w"]
    print("restored", float(np.asarray(w.addressable_data(0))[0, 0]), len(w.sharding.device_set), run.best_score())
"""


def test_two_processes_write_one_checkpoint_and_resume_it(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    workers = [subprocess.Popen([sys.executable, "-c", TWO_PROCESSES, str(i), str(port), str(tmp_path)], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outputs = [w.communicate(timeout=120) for w in workers]
    assert [w.returncode for w in workers] == [0, 0], [err[-2000:] for _, err in outputs]
    assert [out.splitlines()[-1].split() for out, _ in outputs] == [["restored", "3.0", "2", "7.0"]] * 2
    assert [p.name for p in last_steps(tmp_path)] == ["step_0000002", "step_0000003"]
    assert best_step(tmp_path).name == "step_0000002"
    np.testing.assert_array_equal(read_state(last_steps(tmp_path)[-1])["params"]["w"], np.full((4, 4), 3.0))

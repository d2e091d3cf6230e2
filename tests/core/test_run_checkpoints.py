"""core.run_checkpoints: Orbax's managers for a run's last-N and best states. A kill -9 while an
asynchronous save writes leaves the previous checkpoint to resume from, keep-N and the best hold
apart, the loop may donate a state as soon as its save returns, and a run directory of msgpack
checkpoints is converted on its first resume."""

import os
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


def test_keep_n_holds_and_the_best_is_kept_apart(tmp_path):
    with RunCheckpoints(tmp_path, keep=2, best_key="mAP") as run:
        for step in range(1, 6):
            run.save(step, state(float(step)), {"loss": float(step)})
            if step in (1, 3):
                run.save_best(step, state(float(step)), 10.0 * step, {"eval": {"mAP": 10.0 * step}})
        assert run.latest().name == "step_0000005"
        assert run.best_score() == 30.0
    assert [p.name for p in last_steps(tmp_path)] == ["step_0000004", "step_0000005"]
    best = best_step(tmp_path)
    assert best.name == "step_0000003" and read_extra(best) == {"step": 3, "mAP": 30.0, "eval": {"mAP": 30.0}}
    assert read_state(tmp_path / "checkpoints" / "best")["params"]["w"][0, 0] == 3.0  # the manager dir reads its step


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

"""TensorBoard event files and the weight EMA through the shared loop, on a toy linear model that
brings its own step (as the depth trainer does): the loop's bookkeeping, not a network, is tested;
tests/train/test_train_step.py checks the EMA inside the real train step."""

import dataclasses
import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from dsfec_jax.core import checkpoint
from dsfec_jax.core.png import png_bytes
from dsfec_jax.train import ema
from dsfec_jax.core.run_checkpoints import last_steps, read_state
from dsfec_jax.train.loop import RunMismatch, RunSpec, train
from dsfec_jax.train.schedules import get_schedule, learning_rate
from dsfec_jax.train.sgd_recipe import make_recipe, ultralytics_sgd
from builders import tensorboard_events


@dataclasses.dataclass(frozen=True)
class ToyConfig:
    features: int = 3


class ToyDetector:
    """y = x.w + b with a running mean of x as its 'batch_stats'; its step updates the average as
    train/step.py's does."""

    name = "toy"
    config = ToyConfig()
    collections = ("params", "batch_stats")

    def init(self, rng) -> dict:
        return {"params": {"w": jax.random.normal(rng, (3,)), "b": jnp.zeros(())}, "batch_stats": {"mean": jnp.zeros(3)}}

    def variable_shapes(self) -> dict:  # what zoo.load_variables checks a checkpoint against
        return jax.eval_shape(self.init, jax.random.key(0))

    def make_train_step(self, tx):
        def step(state, batch):
            x, y = batch["inputs"]["x"], batch["targets"]["y"]
            loss, grads = jax.value_and_grad(lambda p: jnp.mean((x @ p["w"] + p["b"] - y) ** 2))(state["params"])
            updates, opt_state = tx.update(grads, state["opt_state"], state["params"])
            new = {**state, "params": optax.apply_updates(state["params"], updates), "opt_state": opt_state,
                   "batch_stats": {"mean": 0.9 * state["batch_stats"]["mean"] + 0.1 * x.mean(0)},
                   "step": state["step"] + 1}
            return ema.updated(state, new), {"loss": loss, "grad_norm": optax.tree.norm(grads), "half": loss / 2}

        return jax.jit(step, donate_argnums=0)


class ToyStream:
    batch_size = 4

    def batch(self, step: int) -> dict:
        x = np.random.default_rng(step).normal(size=(4, 3)).astype(np.float32)
        return {"inputs": {"x": x}, "targets": {"y": x @ np.float32([1.0, -2.0, 0.5]) + 0.3}, "window": 0}


def run(tmp_path, name, stop_at=None, ema_on=True, info=None):
    sched = get_schedule("quick", learning_rate=0.05, warmup_steps=2, batch_size=4, steps=6, ema=ema_on)
    spec = RunSpec(tmp_path / name, sched, seed=1, total_steps=6, stop_at=stop_at, log_every=1, ckpt_every=2,
                   progress=False)
    validate = lambda state: {"b": float(ema.evaluated(state)["params"]["b"]), "per_class": {"car": 0.5}, "tag": "x"}
    picture = lambda state: png_bytes(np.full((4, 6, 3), 200, np.uint8))
    info = {"schedule": json.loads(json.dumps(dataclasses.asdict(sched))), **(info or {"test": True})}
    state, _ = train(ToyDetector(), ToyStream(), spec, info, validate, 3, best_key="b", picture=picture)
    return state, spec


def test_the_average_is_ultralytics_model_ema():
    """d = 0.9999 (1 - exp(-updates / 2000)), ema = d ema + (1 - d) current, over params and BN
    statistics, counted per optimizer step; integers and batches without a step leave it alone."""
    average = {"params": {"w": np.float32([1.0, -1.0])}, "batch_stats": {"m": np.float32([0.5]), "n": np.int32(7)},
               "updates": jnp.zeros((), jnp.int32)}
    expected = {"w": np.float64([1.0, -1.0]), "m": np.float64([0.5])}
    for k, stepped in enumerate([True, True, False, True]):
        current = {"params": {"w": np.float32([k, 2 * k])}, "batch_stats": {"m": np.float32([-k]), "n": np.int32(9)}}
        average = ema.averaged(average, current, jnp.asarray(stepped))
        if stepped:
            d = 0.9999 * (1 - np.exp(-int(average["updates"]) / 2000))
            expected = {"w": d * expected["w"] + (1 - d) * np.float64([k, 2 * k]),
                        "m": d * expected["m"] + (1 - d) * np.float64([-k])}
        np.testing.assert_allclose(average["params"]["w"], expected["w"], rtol=1e-6)
        np.testing.assert_allclose(average["batch_stats"]["m"], expected["m"], rtol=1e-6)
    assert int(average["updates"]) == 3 and int(average["batch_stats"]["n"]) == 7
    assert float(ema.decay(2000)) == pytest.approx(0.9999 * (1 - np.exp(-1)))


def test_the_average_steps_with_an_accumulating_optimizer():
    """Under ultralytics' accumulation (4 batches an optimizer step here) ModelEMA updates once per
    optimizer step: on the batches that change the weights."""
    recipe = make_recipe(lr0=0.01, final_lr_fraction=0.01, momentum=0.9, warmup_momentum=0.8, warmup_bias_lr=0.1,
                         warmup_epochs=0, min_warmup_iters=0, epochs=1, steps_per_epoch=12, batch_size=16,
                         nominal_batch=64, weight_decay=0.0, clip_norm=10.0)
    tx = ultralytics_sgd(recipe)
    params = {"w": jnp.ones(2)}
    opt_state, stepped, update = tx.init(params), [], jax.jit(tx.update)
    for _ in range(8):
        updates, new_state = update({"w": jnp.ones(2)}, opt_state, params)
        stepped.append(bool(ema.optimizer_stepped(opt_state, new_state)))
        assert stepped[-1] == bool(jnp.any(updates["w"] != 0))
        opt_state = new_state
    assert stepped == [False, False, False, True] * 2
    assert bool(ema.optimizer_stepped(optax.sgd(0.1).init(params), optax.sgd(0.1).init(params)))  # not accumulating


def test_event_files_hold_the_logged_scalars_and_a_resume_keeps_the_average_exact(tmp_path):
    """Stopped at step 4 and as if killed before its checkpoint landed: the resume from step 2
    logs steps 3-4 again, and TensorBoard's reader shows each step once, with the resumed run's
    values. The average (validated, checkpointed) ends bit for bit as in a straight run."""
    straight, _ = run(tmp_path, "straight")
    _, spec = run(tmp_path, "resumed", stop_at=4)
    last = last_steps(spec.run_dir)[-1]
    assert last.name == "step_0000004"
    shutil.rmtree(last)
    resumed, spec = run(tmp_path, "resumed")
    jax.tree.map(np.testing.assert_array_equal, resumed["ema"], straight["ema"])
    assert int(resumed["ema"]["updates"]) == 6
    # an average, not a copy: six updates into the ramp (d ~ 0.003) it trails the weights a little,
    # far above float32's rounding of these values (~1e-8)
    assert np.abs(resumed["ema"]["params"]["w"] - resumed["params"]["w"]).max() > 1e-7

    reader = tensorboard_events(spec.run_dir)
    rows = [json.loads(line) for line in (spec.run_dir / "metrics.jsonl").read_text().splitlines()]
    losses = {r["step"]: r["loss"] for r in rows if "loss" in r}
    assert [(e.step, pytest.approx(e.value)) for e in reader.Scalars("train/loss")] == sorted(losses.items())
    assert {"train/grad_norm", "train/half", "train/frames_per_s"} <= set(reader.Tags()["scalars"])
    rate = learning_rate(spec.schedule, 6)
    assert [(e.step, pytest.approx(e.value)) for e in reader.Scalars("train/lr")] == [
        (s, pytest.approx(float(rate(s - 1)))) for s in range(1, 7)]
    assert [e.step for e in reader.Scalars("val/per_class/car")] == [3, 6] and "val/tag" not in reader.Tags()["scalars"]
    assert reader.Scalars("val/b")[-1].value == pytest.approx(float(resumed["ema"]["params"]["b"]))  # the average's
    assert [e.step for e in reader.Images("val/predictions")] == [3, 6]


def test_tensorboard_can_be_turned_off_and_a_run_from_before_the_average_says_how_to_resume(tmp_path, monkeypatch):
    """run.json "tensorboard": false writes no event file (a launch setting: a resume may change
    it), nor does any process but the first of a multi-host run. A run started before the average
    existed (its run.json schedule has no 'ema') resumes without one, and is refused, naming the
    field, when the resume asks for one."""
    from dsfec_jax.train.tensorboard import Board

    with monkeypatch.context() as m:
        m.setattr(jax, "process_index", lambda: 1)
        with Board(tmp_path / "second_host", 0, None) as board:
            board.training(1, {"loss": 1.0})
        assert not (tmp_path / "second_host").exists()
    run(tmp_path, "old", stop_at=2, ema_on=False, info={"test": True, "tensorboard": False})
    assert not list((tmp_path / "old").glob("events.out.tfevents.*"))
    record = json.loads((tmp_path / "old" / "run.json").read_text())
    del record["schedule"]["ema"]
    (tmp_path / "old" / "run.json").write_text(json.dumps(record))
    assert "ema" not in read_state(last_steps(tmp_path / "old")[-1])
    with pytest.raises(RunMismatch, match=r"schedule\.ema=\"<absent>\"; the command asks schedule\.ema=true.*"
                                          r"started before runs kept a weight EMA: resume it with --no-ema\."):
        run(tmp_path, "old", ema_on=True)
    state, _ = run(tmp_path, "old", stop_at=4, ema_on=False)
    assert "ema" not in state and int(state["step"]) == 4
    assert list((tmp_path / "old").glob("events.out.tfevents.*"))


def test_a_checkpoint_with_an_average_ships_the_average(tmp_path):
    """`dsfec ship`, `--weights` and warm starts read a checkpoint through zoo.load_variables: a
    run that kept an average validated it, so the average is what they get (shape-checked)."""
    from dsfec_jax import zoo

    det = ToyDetector()
    raw, average = det.init(jax.random.key(0)), det.init(jax.random.key(1))
    path = tmp_path / "step_0000003.msgpack"
    checkpoint.save(path, {**raw, "step": 3, "ema": {**average, "updates": 3}})
    jax.tree.map(np.testing.assert_array_equal, zoo.model_variables(det, path), average)
    checkpoint.save(path, {**raw, "step": 3, "ema": {**average, "params": {**average["params"], "w": np.zeros(2)}}})
    with pytest.raises(ValueError, match=r"\['ema'\]\['params'\]\['w'\] has shape \(2,\)"):
        zoo.model_variables(det, path)
    checkpoint.save(path, raw)  # weights without an average load as before
    jax.tree.map(np.testing.assert_array_equal, zoo.model_variables(det, path), raw)


def test_the_yolo_and_camera_families_train_with_the_average_unless_told():
    """`dsfec train` asks the family (Family.weight_ema): on for the range-Doppler YOLOs and the
    camera models, off for DSFEC and RadarNeXt; --ema / --no-ema override it."""
    from dsfec_jax import zoo
    from dsfec_jax.cli import parse, training_schedule

    def ema_of(model, *flags):
        args = parse(["train", "--model", model, "--run-dir", "unused", *flags])
        return training_schedule(args, zoo.family_of(zoo.config(model))).ema

    assert [ema_of(m) for m in ("yolov8n", "yolov8n_adapter", "shuffle_yolov3", "dsfec_s", "radarnext_pan")] == [
        True, True, True, False, False]
    assert (ema_of("yolov8n", "--no-ema"), ema_of("dsfec_s", "--ema")) == (False, True)

import json

import jax
import numpy as np
import pytest

from dsfec_jax.core.run_checkpoints import last_steps, read_extra, read_state
from dsfec_jax.data.batches import BatchStream
from dsfec_jax.data.points.pillarize import PillarSpec
from dsfec_jax import zoo
from dsfec_jax.train.loop import RunSpec, TrainingDiverged, train
from dsfec_jax.train.schedules import get_schedule, optimizer
from dsfec_jax.train.step import init_state, make_train_step
from conftest import tiny
from builders import assert_rows_are_the_batch_rows, toy_frame


def setup(tmp_path, name, lr=2e-3, total=6, stop_at=None, ckpt_every=2, log_every=1):
    # one block per stage, one conv per head: the loop's bookkeeping does not depend on depth, and
    # a shallower network compiles its init and step faster (each schedule here is its own program)
    det = tiny("dsfec_s", stage_blocks=(1, 1, 1, 1), head_convs=1)
    frames = [toy_frame(np.random.default_rng(i), det.config.grid) for i in range(6)]
    stream = BatchStream(frames, PillarSpec.of(det.config), zoo.family_of(det.config).points.targets(det.config),
                         batch_size=2, seed=7)
    sched = get_schedule("quick", learning_rate=lr, warmup_steps=2, batch_size=2, steps=total)
    spec = RunSpec(tmp_path / name, sched, seed=3, total_steps=total, stop_at=stop_at, log_every=log_every,
                   ckpt_every=ckpt_every, keep=2, progress=False)
    return det, stream, spec


def test_batches_are_a_pure_function_of_the_step(tmp_path):
    _, stream, _ = setup(tmp_path, "x")
    a, b = stream.batch(4), stream.batch(4)
    jax.tree.map(np.testing.assert_array_equal, a["inputs"], b["inputs"])
    assert sorted(np.concatenate([stream.indices(s) for s in range(3)]).tolist()) == list(range(6))


def test_a_slice_of_rows_is_those_rows_of_the_batch(tmp_path):
    _, stream, _ = setup(tmp_path, "x")
    assert_rows_are_the_batch_rows(stream, 4, slice(1, 2))


def test_resumed_run_ends_with_the_same_parameters(tmp_path, caplog):
    """Stopped after step 3, and as if killed twice: while saving step 3 (Orbax's temporary
    directory, which a kill mid-write leaves) and while logging step 4 (a torn last line). The
    resume goes back to step 2 and removes the torn step."""
    det, stream, spec = setup(tmp_path, "straight")
    straight, _ = train(det, stream, spec, {"test": True})
    det, stream, spec = setup(tmp_path, "resumed", stop_at=3)
    train(det, stream, spec, {"test": True})
    assert [p.name for p in last_steps(spec.run_dir)] == ["step_0000002", "step_0000003"]
    torn = last_steps(spec.run_dir)[-1]
    torn.rename(torn.with_name(torn.name + ".orbax-checkpoint-tmp-1"))
    log_path = spec.run_dir / "metrics.jsonl"
    log_path.write_text(log_path.read_text() + '{"step": 4, "frames_per_s": 1')
    det, stream, spec = setup(tmp_path, "resumed")
    resumed, _ = train(det, stream, spec, {"test": True})
    assert int(resumed["step"]) == int(straight["step"]) == 6
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7), straight["params"], resumed["params"])
    steps = [json.loads(l)["step"] for l in log_path.read_text().splitlines()]
    assert steps == [1, 2, 3, 4, 5, 6]
    assert sorted(p.name for p in torn.parent.iterdir()) == ["step_0000004", "step_0000006"]  # keep=2, torn removed
    assert f"{log_path}: dropped its torn last line" in caplog.text


def test_a_resume_must_ask_for_the_setup_the_run_started_with(tmp_path):
    """run.json is the run's provenance: a resume with another seed or length is refused, naming
    the fields, and leaves it untouched; a true resume (another command line, other versions) is
    appended to its "resumes". A run stopped before its first checkpoint is held to it too."""
    from dsfec_jax.train.loop import RunMismatch

    started = {"command": "dsfec train --seed 3", "seed": 3, "steps": 6, "config": {"stem_filters": 8, "act": "relu"},
               "versions": {"jax": "0.1"}}
    det, stream, spec = setup(tmp_path, "run", stop_at=0)
    train(det, stream, spec, started)
    assert not last_steps(spec.run_dir)
    run_json = (spec.run_dir / "run.json").read_text()
    asked = {**started, "seed": 4, "steps": 7, "config": {"stem_filters": 8, "act": "mish"}}
    with pytest.raises(RunMismatch, match=r"run\.json: this run was started with seed=3, steps=6, config\.act=\"relu\"; "
                                          r"the command asks seed=4, steps=7, config\.act=\"mish\"\. Use a new run directory"):
        train(det, stream, spec, asked)
    assert (spec.run_dir / "run.json").read_text() == run_json
    train(det, stream, spec, {**started, "command": "dsfec train --seed 3 --eval-every 5", "versions": {"jax": "0.2"}})
    info = json.loads((spec.run_dir / "run.json").read_text())
    assert info["command"] == started["command"] and info["versions"] == {"jax": "0.1"}
    assert [{k: r[k] for k in ("from_step", "command", "versions")} for r in info["resumes"]] == [
        {"from_step": 0, "command": "dsfec train --seed 3 --eval-every 5", "versions": {"jax": "0.2"}}]


def test_divergence_stops_with_the_last_good_checkpoint_intact(tmp_path):
    det, stream, spec = setup(tmp_path, "nan", lr=1e12, total=8, ckpt_every=1)
    with pytest.raises(TrainingDiverged, match="Last good checkpoint"):
        train(det, stream, spec, {"test": True})
    last = last_steps(spec.run_dir)
    assert last, "at least one good step should have been checkpointed"
    tree = read_state(last[-1])
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(tree["params"]))


def logged(run_dir):
    """metrics.jsonl rows without their timing."""
    rows = [json.loads(l) for l in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if k != "frames_per_s"} for r in rows]


def test_runs_are_deterministic_and_losses_read_late_are_the_steps_own(tmp_path):
    """Two runs log the same rows bit for bit, those of training step s on stream.batch(s) one step
    at a time; so does a run stopped after step 3 and resumed.
    Losses stay on the device until a log step reads them: a run logging every 3rd step logs
    exactly the rows of one logging every step, at those steps."""
    for name in ("a", "b"):
        det, stream, spec = setup(tmp_path, name)
        train(det, stream, spec, {"test": True})
    straight = logged(tmp_path / "a")
    assert [r["step"] for r in straight] == [1, 2, 3, 4, 5, 6]
    assert len({r["loss"] for r in straight}) == 6  # the rows differ from step to step: the test can fail
    assert logged(tmp_path / "b") == straight
    det, stream, spec = setup(tmp_path, "replay")  # step s trains on stream.batch(s), read at once
    tx = optimizer(spec.schedule, spec.total_steps)
    state, step_fn = init_state(det, tx, jax.random.key(spec.seed)), make_train_step(det, tx)
    replayed = []
    for s in range(6):
        batch = stream.batch(s)
        state, metrics = step_fn(state, {"inputs": batch["inputs"], "targets": batch["targets"]})
        replayed.append(float(metrics["loss"]))
    assert replayed == [r["loss"] for r in straight]
    det, stream, spec = setup(tmp_path, "resumed", stop_at=3)
    train(det, stream, spec, {"test": True})
    det, stream, spec = setup(tmp_path, "resumed")
    train(det, stream, spec, {"test": True})
    assert logged(tmp_path / "resumed") == straight
    det, stream, spec = setup(tmp_path, "sparse", log_every=3)
    train(det, stream, spec, {"test": True})
    assert logged(tmp_path / "sparse") == [r for r in straight if r["step"] in (3, 6)]
    manifest = read_extra(last_steps(spec.run_dir)[-1])
    assert manifest["loss"] == straight[-1]["loss"]


def poison(stream, at):
    """The stream with non-finite inputs at step `at`: the loss becomes NaN at exactly that step."""
    clean = stream.batch

    def batch(step):
        b = clean(step)
        if step == at:
            b["inputs"] = {**b["inputs"], "points": np.full_like(b["inputs"]["points"], np.nan)}
        return b

    stream.batch = batch
    return stream


def test_divergence_between_log_steps_is_caught_before_the_next_checkpoint(tmp_path):
    """Losses are read at log and checkpoint steps only: a NaN at step 4 (logged every 100 steps,
    saved every 3) is named with its step when step 6 is about to be saved, and no checkpoint
    holds the diverged state."""
    det, stream, spec = setup(tmp_path, "nan", total=8, ckpt_every=3, log_every=100)
    message = r"loss is nan at step 4; stopped\. Last good checkpoint: .*checkpoints/last/step_0000003$"
    with pytest.raises(TrainingDiverged, match=message):
        train(det, poison(stream, at=4), spec, {"test": True})
    assert [p.name for p in last_steps(spec.run_dir)] == ["step_0000003"]
    tree = read_state(last_steps(spec.run_dir)[-1])
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(tree))


def test_training_windows_cover_the_grid_with_equal_shapes():
    from dsfec_jax.data.batches import training_windows
    from dsfec_jax.core.grid import DSFEC_GRID

    windows = training_windows(DSFEC_GRID, 96)
    assert {w.shape for w in windows} == {(96, 96)} and len(windows) == 4
    assert min(w.x_range[0] for w in windows) == 0 and max(w.x_range[1] for w in windows) == 80
    assert min(w.y_range[0] for w in windows) == -40 and max(w.y_range[1] for w in windows) == 40
    assert training_windows(DSFEC_GRID, None) == [DSFEC_GRID] == training_windows(DSFEC_GRID, 160)


def test_object_window_sampling_favours_windows_with_boxes():
    """TJ4D-like sparsity: every car in one of 25 windows. Cycling gives it 1 step in 25; 'objects'
    about OBJECT_WINDOW_SHARE of the steps, and a batch's window is still a function of its step."""
    from dsfec_jax.data import batches
    from dsfec_jax.data.points.frame import Boxes, Frame
    from dsfec_jax.core.grid import TJ4D_GRID

    windows = batches.training_windows(TJ4D_GRID, 96)
    assert len(windows) == 25
    car = Boxes(np.array([[20.0, 1.0, 0.0]]), np.array([[1.8, 4.2, 1.5]]), np.zeros(1), np.zeros((1, 2)),
                np.array(["car"]))
    frames = [Frame(np.zeros((0, 4), np.float32), ("x", "y", "z", "rcs"), car, f"f{i}") for i in range(4)]
    specs = [PillarSpec(w, ("x", "y", "z", "rcs"), 8, 2) for w in windows]
    holding = {i for i, w in enumerate(windows) if w.x_range[0] <= 20 < w.x_range[1] and w.y_range[0] <= 1 < w.y_range[1]}

    def share(sampling):
        stream = BatchStream(frames, specs, lambda boxes, grid: {}, 2, seed=0, augment_cfg=None,
                             window_sampling=sampling)
        picked = [stream.window(s, [frames[0]]) for s in range(400)]
        assert picked[:50] == [stream.window(s, [frames[0]]) for s in range(50)]
        return np.mean([p in holding for p in picked])

    assert share("cycle") == pytest.approx(len(holding) / 25, abs=0.01)
    assert share("objects") == pytest.approx(batches.OBJECT_WINDOW_SHARE + 0.2 * len(holding) / 25, abs=0.06)
    with pytest.raises(ValueError, match="window_sampling must be one of"):
        BatchStream(frames, specs, lambda boxes, grid: {}, 2, seed=0, window_sampling="random")


def test_a_run_started_before_a_schedule_field_existed_resumes_at_its_default(tmp_path):
    """run.json of an older version lacks Schedule fields added since (optimizer, momentum, ...):
    at their defaults the setup is the same; at another value it is a new setup."""
    import dataclasses

    from dsfec_jax.core import atomic
    from dsfec_jax.train.loop import RunMismatch, _started_with
    from dsfec_jax.train.schedules import get_schedule

    schedule = dataclasses.asdict(get_schedule("quick"))
    old = {k: v for k, v in schedule.items() if k not in ("optimizer", "momentum")}
    atomic.write_json(tmp_path / "run.json", {"seed": 0, "schedule": old})
    assert _started_with(tmp_path, {"seed": 0, "schedule": schedule}) is not None
    with pytest.raises(RunMismatch, match="schedule.optimizer"):
        _started_with(tmp_path, {"seed": 0, "schedule": {**schedule, "optimizer": "sgd"}})


def test_a_run_started_before_a_config_field_existed_resumes_at_its_default(tmp_path):
    """The same for the model's config (YOLO's elastic width ratios came after the RD tables' runs)."""
    import dataclasses

    from dsfec_jax import zoo
    from dsfec_jax.core import atomic
    from dsfec_jax.core.provenance import jsonable
    from dsfec_jax.train.loop import RunMismatch, _started_with

    cfg = zoo.config("yolov8n")
    config = jsonable(dataclasses.asdict(cfg))
    old = {k: v for k, v in config.items() if k not in ("backbone_width_ratios", "neck_width_ratios")}
    atomic.write_json(tmp_path / "run.json", {"seed": 0, "config": old})
    assert _started_with(tmp_path, {"seed": 0, "config": config}, type(cfg)) is not None
    with pytest.raises(RunMismatch, match="config.neck_width_ratios"):
        _started_with(tmp_path, {"seed": 0, "config": {**config, "neck_width_ratios": [0.5, 1.0, 1.0]}}, type(cfg))
    with pytest.raises(RunMismatch, match="config.backbone_width_ratios"):  # without the config's type: no defaults
        _started_with(tmp_path, {"seed": 0, "config": config})

import json

import jax
import numpy as np
import pytest

from dsfec_jax.core import checkpoint
from dsfec_jax.data.batches import BatchStream
from dsfec_jax.data.points.pillarize import PillarSpec
from dsfec_jax import zoo
from dsfec_jax.train.loop import RunSpec, TrainingDiverged, checkpoints, train
from dsfec_jax.train.schedules import get_schedule
from conftest import tiny
from builders import toy_frame


def setup(tmp_path, name, lr=2e-3, total=6, stop_at=None, ckpt_every=2):
    det = tiny("dsfec_s")
    frames = [toy_frame(np.random.default_rng(i), det.config.grid) for i in range(6)]
    stream = BatchStream(frames, PillarSpec.of(det.config), zoo.family_of(det.config).targets(det.config),
                         batch_size=2, seed=7)
    sched = get_schedule("quick", learning_rate=lr, warmup_steps=2, batch_size=2, steps=total)
    spec = RunSpec(tmp_path / name, sched, seed=3, total_steps=total, stop_at=stop_at, log_every=1,
                   ckpt_every=ckpt_every, keep=2, progress=False)
    return det, stream, spec


def test_batches_are_a_pure_function_of_the_step(tmp_path):
    _, stream, _ = setup(tmp_path, "x")
    a, b = stream.batch(4), stream.batch(4)
    jax.tree.map(np.testing.assert_array_equal, a["inputs"], b["inputs"])
    assert sorted(np.concatenate([stream.indices(s) for s in range(3)]).tolist()) == list(range(6))


def test_resumed_run_ends_with_the_same_parameters(tmp_path, caplog):
    """Stopped after step 3, and as if killed twice: while saving step 3 (its manifest never
    landed) and while logging step 4 (a torn last line). The resume goes back to step 2."""
    det, stream, spec = setup(tmp_path, "straight")
    straight, _ = train(det, stream, spec, {"test": True})
    det, stream, spec = setup(tmp_path, "resumed", stop_at=3)
    train(det, stream, spec, {"test": True})
    assert [p.name for p in checkpoints(spec.run_dir)] == ["step_0000002.msgpack", "step_0000003.msgpack"]
    checkpoint.manifest_path(checkpoints(spec.run_dir)[-1]).unlink()
    log_path = spec.run_dir / "metrics.jsonl"
    log_path.write_text(log_path.read_text() + '{"step": 4, "frames_per_s": 1')
    det, stream, spec = setup(tmp_path, "resumed")
    resumed, _ = train(det, stream, spec, {"test": True})
    assert int(resumed["step"]) == int(straight["step"]) == 6
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7), straight["params"], resumed["params"])
    steps = [json.loads(l)["step"] for l in log_path.read_text().splitlines()]
    assert steps == [1, 2, 3, 4, 5, 6]
    assert [p.name for p in checkpoints(spec.run_dir)] == ["step_0000004.msgpack", "step_0000006.msgpack"]  # keep=2
    assert all(checkpoint.problem(p) is None for p in checkpoints(spec.run_dir))
    assert "step_0000003.msgpack.json: manifest missing" in caplog.text
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
    assert not checkpoints(spec.run_dir)
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
    last = checkpoints(spec.run_dir)
    assert last, "at least one good step should have been checkpointed"
    tree = checkpoint.load(last[-1])
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(tree["params"]))


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

"""Training the camera family: multi-scale batches trace the jitted step once per input size, a
resumed run ends with the losses and parameters of an uninterrupted one, and the darknet schedule
is yolov3-voc.cfg's. A tiny Shuffle-YOLOv3 on 64-96 px inputs (compiles dominate: ~30 s a size
here); `fit_camera` with its validation is exercised by tests/modalities/image/test_image_cli.py's round trip."""

from __future__ import annotations

import functools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.data.camera.augment import CameraAugment
from dsfec_jax.data.camera.batches import CameraBatchStream, MultiScale
from dsfec_jax.data.camera.sources import load_camera_images
from dsfec_jax.models.camera import family as camera_family
from dsfec_jax.models.camera.targets import pad_batch
from dsfec_jax.modalities.image.fit import multi_scale_for
from dsfec_jax.train.loop import RunSpec, train
from dsfec_jax.train.schedules import get_schedule, learning_rate, optimizer

STREET = ("car", "truck", "bus", "pedestrian", "cyclist")
TINY = dict(widths=(16, 16, 32, 32, 64), repeats=(1, 1, 1, 1, 1), head_widths=(16, 32, 64), head_units=1,
            num_classes=5, class_names=STREET)
SIZES = MultiScale((64, 96), every=1)
STEPS, SEED = 3, 2  # seed 2 draws sizes 96, 64, 64 for steps 0-2: two sizes, one of them twice


def test_one_trace_per_input_size_and_a_resumed_run_is_the_straight_one(tmp_path, monkeypatch, caplog, uncompiled_init):
    """Also: the boxes that 4 slots an image cut off reach metrics.jsonl, and one warning."""
    det = zoo.create("shuffle_yolov3", **TINY)
    targets = functools.partial(pad_batch, class_names=det.config.classes, max_boxes=4)
    stream = CameraBatchStream(load_camera_images("street", "train", 2, seed=0), 2, SEED, targets, CameraAugment(),
                               SIZES)
    shapes = [stream.input_hw(k) for k in range(STEPS)]
    assert len(set(shapes)) == 2 < len(shapes), shapes
    traced = []
    loss = camera_family.yolo3_loss  # the family's loss: called once per trace of the train step

    def counting_loss(outputs, *args):
        traced.append(tuple(outputs[0].shape[1:3]))
        return loss(outputs, *args)

    monkeypatch.setattr(camera_family, "yolo3_loss", counting_loss)
    schedule = get_schedule("yolo3_quick", batch_size=2, warmup_steps=1)

    def run(name, stop_at=None):
        spec = RunSpec(tmp_path / name, schedule, seed=0, total_steps=STEPS, stop_at=stop_at, log_every=1,
                       ckpt_every=100, progress=False)
        return train(det, stream, spec, {"test": True})[0]

    straight = run("straight")
    assert len(traced) == len(set(shapes)) == 2, traced  # one trace per size, the repeated size reused
    run("resumed", stop_at=1)
    resumed = run("resumed")
    rows = {name: [json.loads(l) for l in (tmp_path / name / "metrics.jsonl").read_text().splitlines()]
            for name in ("straight", "resumed")}
    assert [r["step"] for r in rows["resumed"]] == [1, 2, 3] and all(np.isfinite(r["loss"]) for r in rows["straight"])
    cut_off = [stream.batch(k)["stats"]["dropped_boxes"] for k in range(STEPS)]
    assert [r["dropped_boxes"] for r in rows["straight"]] == cut_off and cut_off[0] > 0, cut_off
    warned = [r.getMessage() for r in caplog.records if r.name == "dsfec_jax.train.dropped_boxes"]
    assert len(warned) == 3 and f"cut off {cut_off[0]} ground-truth box(es)" in warned[0]  # once per train()
    assert "max_boxes=4" in warned[0]
    np.testing.assert_allclose([r["loss"] for r in rows["resumed"]], [r["loss"] for r in rows["straight"]],
                               rtol=1e-5)
    assert int(resumed["step"]) == int(straight["step"]) == STEPS
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6), straight["params"],
                 resumed["params"])


def test_the_paper_schedule_is_yolov3_voc_cfg():
    s = get_schedule("yolo3_paper")
    assert (s.batch_size, s.learning_rate, s.momentum, s.weight_decay, s.warmup_steps, s.steps) == (
        64, 0.001, 0.9, 5e-4, 1000, 50200)
    lr = learning_rate(s, s.steps)
    assert float(lr(500)) == pytest.approx(0.001 * 0.5**4)  # burn_in, power 4
    assert [float(lr(t)) for t in (1000, 39999, 40000, 44999, 45000, 50199)] == pytest.approx(
        [1e-3, 1e-3, 1e-4, 1e-4, 1e-5, 1e-5])
    params = {"conv": {"kernel": jnp.ones((3, 3, 2, 2)), "bias": jnp.ones(2)}, "bn": {"scale": jnp.ones(2)}}
    tx = optimizer(s, s.steps)
    state = tx.init(params)
    zero = jax.tree.map(jnp.zeros_like, params)
    for _ in range(1001):  # past burn-in with zero gradients: only the decay moves anything
        updates, state = tx.update(zero, state, params)
    assert float(updates["conv"]["kernel"][0, 0, 0, 0]) < 0  # kernels decay
    assert float(updates["conv"]["bias"][0]) == 0 and float(updates["bn"]["scale"][0]) == 0  # biases, BN do not
    paper = multi_scale_for(s)  # darknet's random=1: 320..608 every 10 batches, the last 200 at 608
    assert paper.sizes == tuple(range(320, 609, 32)) and (paper.every, paper.final_size, paper.final_steps) == (10, 608, 200)


def test_precise_bn_makes_eval_mode_the_calibration_batchs_train_mode():
    """Calibrated on one batch, the running statistics are that batch's: the eval-mode forward then
    equals the train-mode one; the result does not depend on the statistics it replaces."""
    from conftest import random_variables

    from dsfec_jax.train.precise_bn import precise_bn

    det = zoo.create("shuffle_yolov3", **TINY)
    variables = random_variables(det, 0)
    batch = {"inputs": det.config.dummy_inputs(2, seed=1, hw=(64, 96))}
    calibrate = precise_bn(det, lambda: [batch])
    state = calibrate(variables)
    again = calibrate({**variables, "batch_stats": jax.tree.map(lambda s: s * 3 + 1, variables["batch_stats"])})
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6), state["batch_stats"], again["batch_stats"])
    # a run with a weight EMA validates the average: its statistics are re-estimated, the raw ones kept
    raw = {"params": jax.tree.map(lambda p: p * 1.5, variables["params"]), "batch_stats": variables["batch_stats"]}
    averaged = calibrate({**raw, "ema": {**again, "updates": 1}})
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6), averaged["ema"]["batch_stats"],
                 state["batch_stats"])
    assert averaged["batch_stats"] is raw["batch_stats"]
    train_mode = det.apply(variables, batch["inputs"], train=True)[0]
    eval_mode = det.apply({"params": variables["params"], "batch_stats": state["batch_stats"]}, batch["inputs"])
    before = det.apply(variables, batch["inputs"])
    for t, e, b in zip(train_mode, eval_mode, before):
        np.testing.assert_allclose(np.asarray(e), np.asarray(t), rtol=1e-3, atol=1e-3)
        assert not np.allclose(np.asarray(b), np.asarray(t), atol=1e-3)  # the random statistics were not

import jax
import numpy as np
import pytest

from dsfec_jax.data.points.pillarize import PillarSpec, pillarize_frames
from dsfec_jax.models.dsfec.targets import detector_targets
from dsfec_jax.models.dsfec.net import HEAD_NAMES
from dsfec_jax.models.dsfec.loss import LossConfig, detection_loss, sigmoid_focal_loss, smooth_l1
from dsfec_jax.train.schedules import get_schedule, learning_rate, optimizer
from dsfec_jax.train.ema import with_ema
from dsfec_jax.train.step import batch_on_device, init_state, make_train_step
from conftest import random_variables, tiny
from builders import toy_frame


def toy_batch(det, n=2):
    cfg = det.config
    frames = [toy_frame(np.random.default_rng(i), cfg.grid) for i in range(n)]
    inputs, _ = pillarize_frames(frames, PillarSpec.of(cfg))
    heads = dict(zip(HEAD_NAMES, cfg.head_classes))
    targets = [detector_targets(f.boxes, heads, cfg.grid, cfg.output_stride) for f in frames]
    targets = jax.tree.map(lambda *x: np.stack(x), *targets)
    return {"inputs": inputs, "targets": targets}


def test_focal_and_smooth_l1_values():
    assert float(sigmoid_focal_loss(np.array(0.0), np.array(1.0), 0.25, 2.0)) == pytest.approx(0.25 * 0.25 * np.log(2))
    np.testing.assert_allclose(smooth_l1(np.array([0.05, 1.0]), 0.1), [0.0125, 0.95], rtol=1e-6)


def test_a_few_steps_lower_the_loss_and_update_the_weight_average():
    """The step also keeps the weight EMA (train/ema.py) where the state holds one: after each
    step ema = d ema + (1 - d) weights, params and BN statistics alike, d = 0.9999 (1 - exp(-k / 2000))."""
    det = tiny("dsfec_s")
    batch = toy_batch(det)
    sched = get_schedule("quick", warmup_steps=1, learning_rate=3e-3)
    tx = optimizer(sched, 20)
    state = with_ema(init_state(det, tx, jax.random.key(0)), True)
    weights = lambda s: jax.tree.map(lambda x: np.array(x, np.float64), {k: s[k] for k in ("params", "batch_stats")})
    expected = weights(state)
    step = make_train_step(det, tx)
    losses = []
    for k in range(1, 21):
        state, metrics = step(state, batch)
        losses.append(float(metrics["loss"]))
        d = 0.9999 * (1 - np.exp(-k / 2000))
        expected = jax.tree.map(lambda e, w: d * e + (1 - d) * w, expected, weights(state))
    assert np.isfinite(losses).all()
    assert np.mean(losses[-3:]) < 0.5 * losses[0], losses
    assert int(state["ema"]["updates"]) == 20
    jax.tree.map(lambda a, e: np.testing.assert_allclose(a, e, rtol=1e-5, atol=1e-7), weights(state["ema"]), expected)
    moved = max(np.abs(a - w).max() for a, w in zip(jax.tree.leaves(weights(state["ema"])), jax.tree.leaves(weights(state))))
    assert moved > 1e-3  # 20 steps into the ramp the average still trails the trained weights


def test_targets_give_a_finite_loss_for_all_heads():
    det = tiny("baseline")
    batch = toy_batch(det, 1)
    # init's exact values do not matter for finiteness: stand-in weights of its shapes, jitted apply
    # (compiling init and running the Baseline op by op cost ~20 s)
    variables = random_variables(det, 0)
    loss, parts = detection_loss(jax.jit(det.apply)(variables, batch["inputs"]), batch["targets"], LossConfig())
    assert np.isfinite(float(loss)) and set(parts) == {f"{h}/{k}" for h in HEAD_NAMES for k in ("cls", "box")}


def test_paper_schedule_warms_up_then_decays():
    s = get_schedule("paper")
    assert (s.learning_rate, s.warmup_steps, s.batch_size, s.epochs, s.weight_decay, s.b1) == (0.00348, 400, 24, 30, 0.01, 0.9)
    lr = learning_rate(s, 9000)
    assert float(lr(0)) < float(lr(200)) < float(lr(400)) == pytest.approx(0.00348)
    assert float(lr(7000)) == pytest.approx(0.000348) and float(lr(8500)) == pytest.approx(0.0000348)


def test_batch_on_device_moves_inputs_and_targets_and_keeps_the_rest():
    """The prefetch worker hands the step XLA buffers whose copies are done (so that the step can
    run inline, core/host_memory.py), holding the same values, and leaves the other fields alone."""
    rng = np.random.default_rng(0)
    raw = np.zeros(8 * 3 + 1, np.float32)[1:].reshape(8, 3)  # 4 bytes past an allocation: not 64-byte aligned
    raw[:] = rng.normal(size=(8, 3))
    batch = {"inputs": {"pillars": raw}, "targets": {"car": {"heat": np.arange(6.0).reshape(2, 3)}},
             "window": 3, "stats": {"dropped": 1}}
    moved = batch_on_device(batch)
    for path in (("inputs", "pillars"), ("targets", "car", "heat")):
        before, after = batch, moved
        for key in path:
            before, after = before[key], after[key]
        assert isinstance(after, jax.Array) and after.is_ready()
        np.testing.assert_array_equal(np.asarray(after), before)
    assert moved["window"] == 3 and moved["stats"] is batch["stats"]
    assert isinstance(batch["inputs"]["pillars"], np.ndarray)  # the caller's batch is not changed

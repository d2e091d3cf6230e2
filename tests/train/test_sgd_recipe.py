"""The ultralytics SGD recipe (train/sgd_recipe.py) against hand-computed ultralytics values, and
the older presets against their original formulas."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from dsfec_jax.core import checkpoint
from dsfec_jax.train.schedules import Schedule, get_schedule, learning_rate, optimizer, recipe_for
from dsfec_jax.train.sgd_recipe import (accumulate_at, accumulation_table, learning_rates, momentum_at,
                                        param_groups)


def quick_recipe(epochs=10, total=620, **overrides):
    """yolo_quick over `epochs` epochs of total // epochs batches (62 here: ~1000 samples / 16)."""
    return recipe_for(get_schedule("yolo_quick", epochs=epochs, **overrides), total)


def test_presets_hold_the_ultralytics_numbers():
    paper = get_schedule("yolo_paper")
    assert (paper.optimizer, paper.learning_rate, paper.batch_size, paper.epochs, paper.weight_decay) == \
        ("sgd", 0.01, 64, 300, 5e-4)
    assert (paper.momentum, paper.warmup_momentum, paper.warmup_bias_lr, paper.warmup_epochs,
            paper.final_lr_fraction, paper.nominal_batch, paper.clip_norm, paper.warmup_steps) == \
        (0.937, 0.8, 0.1, 3.0, 0.01, 64, 10.0, 100)
    quick = get_schedule("yolo_quick")
    assert (quick.optimizer, quick.batch_size, quick.epochs, quick.weight_decay) == ("sgd", 16, 15, 5e-4)
    r = quick_recipe()
    # nw = max(round(3 * 62), 100); accumulate = round(64 / 16); decay 5e-4 * 16 * 4 / 64
    assert (r.steps_per_epoch, r.warmup_iters, r.accumulate) == (62, 186, 4)
    assert r.weight_decay == pytest.approx(5e-4)
    assert recipe_for(get_schedule("yolo_quick", batch_size=24), 620).weight_decay == pytest.approx(5e-4 * 24 * 3 / 64)


@pytest.mark.parametrize("step, weight, bias, momentum", [
    (0, 0.0, 0.1, 0.8),                                        # warm-up start: bias lr 0.1, others 0
    (93, 0.5 * 0.00901, 0.1 + 0.5 * (0.00901 - 0.1), 0.8685),  # half-way, epoch 1: lf = 0.9 * 0.99 + 0.01
    (186, 0.00703, 0.00703, 0.937),                            # warm-up end, epoch 3: lf = 0.703
    (62 * 7 + 5, 0.00307, 0.00307, 0.937),                     # epoch 7: lf = 0.307
    (619, 0.00109, 0.00109, 0.937),                            # last epoch: lf = 0.109
])
def test_lr_and_momentum_follow_ultralytics(step, weight, bias, momentum):
    r = quick_recipe()
    lrs = learning_rates(r, step)
    assert float(lrs["weight"]) == pytest.approx(weight, rel=1e-5, abs=1e-9)
    assert float(lrs["no_decay"]) == pytest.approx(weight, rel=1e-5, abs=1e-9)
    assert float(lrs["bias"]) == pytest.approx(bias, rel=1e-5)
    assert float(momentum_at(r, step)) == pytest.approx(momentum, rel=1e-6)
    schedule_lr = learning_rate(get_schedule("yolo_quick", epochs=10), 620)  # what schedules exposes
    assert float(schedule_lr(step)) == pytest.approx(weight, rel=1e-5, abs=1e-9)


def test_short_runs_warm_up_for_at_least_100_batches_and_steps_scale_the_epochs():
    r = recipe_for(get_schedule("yolo_quick", epochs=10), 100)  # --steps 100: 10 batches per epoch
    assert (r.steps_per_epoch, r.warmup_iters) == (10, 100)
    assert float(learning_rates(r, 50)["weight"]) == pytest.approx(0.5 * 0.01 * 0.505, rel=1e-5)  # epoch 5
    step_based = get_schedule("quick", optimizer="sgd", epochs=5)  # steps=600 sets the length
    assert recipe_for(step_based, step_based.total_steps(10_000)).steps_per_epoch == 120


def test_bad_schedules_name_the_field():
    with pytest.raises(ValueError, match="optimizer"):
        Schedule("x", 0.01, 0, 8, epochs=1, optimizer="sgdx")
    with pytest.raises(ValueError, match="epochs"):
        get_schedule("quick", optimizer="sgd")  # step-based without epochs


def test_parameter_groups_follow_ultralytics():
    params = {"Conv_0": {"kernel": jnp.ones((3, 3, 2, 4)), "bias": jnp.ones(4)},
              "BatchNorm_0": {"scale": jnp.ones(4), "bias": jnp.ones(4)},
              "adapter": {"gamma": jnp.zeros(()), "alpha": jnp.zeros(()), "fusion_weight": jnp.zeros(())},
              "mobileone": {"conv0": jnp.ones((3, 3, 2, 4))},
              "dcn": {"dw_kernel": jnp.ones((3, 3, 4)), "dw_bias": jnp.ones(4)}}
    assert param_groups(params) == {
        "Conv_0": {"kernel": "weight", "bias": "bias"},
        "BatchNorm_0": {"scale": "no_decay", "bias": "bias"},
        "adapter": {"gamma": "no_decay", "alpha": "no_decay", "fusion_weight": "no_decay"},
        "mobileone": {"conv0": "weight"}, "dcn": {"dw_kernel": "weight", "dw_bias": "bias"}}


TINY = {"conv": {"kernel": np.array([[1.0, 2.0], [3.0, 4.0]], np.float32)},
        "bn": {"scale": np.array([1.0, 0.5], np.float32), "bias": np.array([0.1, -0.2], np.float32)},
        "adapter": {"gamma": np.array(0.3, np.float32)}}


def grads_like(tree, seed, scale=0.1):
    rng = np.random.default_rng(seed)
    return jax.tree.map(lambda x: (scale * rng.standard_normal(np.shape(x))).astype(np.float32), tree)


def plain_schedule(batch_size=64, **overrides):
    """No warm-up, batch = nbs (no accumulation): lr 0.01 * lf(0) = 0.01, momentum 0.937, wd 5e-4."""
    return get_schedule("yolo_quick", batch_size=batch_size, warmup_epochs=0, epochs=10, **overrides)


def run(tx, params, grads_list):
    state, update = tx.init(params), jax.jit(tx.update)
    for grads in grads_list:
        updates, state = update(grads, state, params)
        params = optax.apply_updates(params, updates)
    return params, state


def hand_sgd(params, grads_list, lr=0.01, m=0.937, wd=5e-4, clip=10.0):
    """torch SGD(nesterov) with decay on 'kernel' only, clip_grad_norm_ first; numpy float64."""
    params = jax.tree.map(np.float64, params)
    buf = None
    for grads in grads_list:
        norm = np.sqrt(sum(np.sum(np.square(np.float64(g))) for g in jax.tree.leaves(grads)))
        coef = min(clip / (norm + 1e-6), 1.0)
        g = {k: {n: coef * np.float64(v) + (wd * params[k][n] if n == "kernel" else 0.0) for n, v in d.items()}
             for k, d in grads.items()}
        buf = g if buf is None else jax.tree.map(lambda b, x: m * b + x, buf, g)
        params = jax.tree.map(lambda p, x, b: p - lr * (x + m * b), params, g, buf)
    return params


@pytest.mark.parametrize("scale", [0.1, 20.0])  # 20: the gradient norm exceeds 10 and is clipped
def test_two_steps_match_hand_computed_nesterov_sgd_with_decay_on_kernels_only(scale):
    grads_list = [grads_like(TINY, 1, scale), grads_like(TINY, 2, scale)]
    got, _ = run(optimizer(plain_schedule(), 100), TINY, grads_list)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7), got, hand_sgd(TINY, grads_list))
    no_decay = hand_sgd(TINY, grads_list, wd=0.0)
    assert not np.allclose(got["conv"]["kernel"], no_decay["conv"]["kernel"], rtol=1e-7, atol=0)  # decay acted


def test_batches_are_summed_to_the_nominal_batch_before_a_step():
    grads_list = [grads_like(TINY, s) for s in range(4)]
    params, state = run(optimizer(plain_schedule(batch_size=16), 400), TINY, grads_list[:3])
    jax.tree.map(np.testing.assert_array_equal, params, TINY)  # no step on the first 3 batches
    params, state = run(optimizer(plain_schedule(batch_size=16), 400), TINY, grads_list)
    summed = jax.tree.map(lambda *g: sum(g), *grads_list)  # the sum, not the mean (loss.backward adds)
    one_step, _ = run(optimizer(plain_schedule(batch_size=64), 100), TINY, [summed])
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-8), params, one_step)
    assert (int(state.count), int(state.last_step)) == (4, 3)
    assert all(not np.any(a) for a in jax.tree.leaves(state.accumulated))


def ultralytics_stepping_batches(nw, nbs, batch, n):
    """The batches on which ultralytics' _do_train calls optimizer_step (8.3 loop, re-typed)."""
    accumulate, last, steps = max(round(nbs / batch), 1), -1, []
    for ni in range(n):
        if ni <= nw:
            accumulate = max(1, int(np.interp(ni, [0, nw], [1, nbs / batch]).round()))
        if ni - last >= accumulate:
            steps.append(ni)
            last = ni
    return steps


def test_the_warm_up_ramps_accumulate_as_ultralytics_does():
    r = quick_recipe()  # nw 186, nbs / batch = 4
    # interp(ni) = 1 + 3 ni / 186, rounded half to even: 31 -> 1.5 -> 2, 93 -> 2.5 -> 2, 155 -> 3.5 -> 4
    batches = (0, 30, 31, 62, 93, 100, 155, 186, 500)
    assert [int(accumulate_at(r, n)) for n in batches] == [1, 1, 2, 2, 2, 3, 4, 4, 4]
    assert len(accumulation_table(r)) == 187
    tx = optimizer(get_schedule("yolo_quick", epochs=10), 620)
    params, state, update = TINY, tx.init(TINY), jax.jit(tx.update)
    stepped = []
    for ni in range(220):
        updates, state = update(grads_like(TINY, 0), state, params)
        if np.any(updates["bn"]["bias"]):  # the bias group's lr is never 0 (the others' is on batch 0)
            stepped.append(ni)
    assert stepped == ultralytics_stepping_batches(186, 64, 16, 220)
    late = [ni for ni in stepped if ni >= 186]
    assert stepped[:3] == [0, 1, 2] and set(np.diff(late)) == {4}  # every batch at first, every 4th after


def test_resume_from_a_checkpoint_mid_accumulation_equals_uninterrupted(tmp_path):
    tx = optimizer(plain_schedule(batch_size=16), 400)  # steps on batches 3 and 7
    grads_list = [grads_like(TINY, s) for s in range(8)]
    straight, _ = run(tx, TINY, grads_list)
    params, state = run(tx, TINY, grads_list[:5])  # one step taken, batch 4 summed, not yet applied
    checkpoint.save(tmp_path / "s.msgpack", {"params": params, "opt_state": state})
    restored = checkpoint.load(tmp_path / "s.msgpack", {"params": TINY, "opt_state": tx.init(TINY)})
    state, update, params = restored["opt_state"], jax.jit(tx.update), restored["params"]
    assert (int(state.count), int(state.last_step)) == (5, 3) and np.any(state.accumulated["conv"]["kernel"])
    for grads in grads_list[5:]:
        updates, state = update(grads, state, params)
        params = optax.apply_updates(params, updates)
    jax.tree.map(np.testing.assert_array_equal, params, straight)


def old_learning_rate(s, total_steps):
    """schedules.learning_rate before the sgd recipe existed (the reference it must still equal)."""
    warmup = optax.linear_schedule(s.learning_rate / 100, s.learning_rate, max(s.warmup_steps, 1))
    boundaries = {max(int(f * total_steps) - s.warmup_steps, 1): s.decay_factor for f in s.decay_at}
    constant = optax.piecewise_constant_schedule(s.learning_rate, boundaries)
    return optax.join_schedules([warmup, constant], [s.warmup_steps])


@pytest.mark.parametrize("name, total", [("quick", 600), ("paper", 9000), ("radarnext", 8000)])
def test_existing_presets_are_unchanged(name, total):
    s = get_schedule(name)
    assert s.optimizer == "adamw"
    new, old = learning_rate(s, total), old_learning_rate(s, total)
    for step in (0, 1, s.warmup_steps // 2, s.warmup_steps, total // 2, int(total * 0.7), int(total * 0.95), total):
        assert float(new(step)) == float(old(step)), step
    old_tx = optax.chain(optax.clip_by_global_norm(s.clip_norm),
                         optax.adamw(old_learning_rate(s, total), b1=s.b1, weight_decay=s.weight_decay))
    grads_list = [grads_like(TINY, k) for k in range(3)]
    jax.tree.map(np.testing.assert_array_equal, run(optimizer(s, total), TINY, grads_list)[0],
                 run(old_tx, TINY, grads_list)[0])

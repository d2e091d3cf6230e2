"""Training pillar slots sized to the data (pillarize.pillar_budget): no pillar is lost in any
window or augmentation, and the network's loss and gradients equal those with the full slots."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.data.batches import BatchStream, training_windows
from dsfec_jax.data.points.pillarize import PillarSpec, pillar_budget
from dsfec_jax.train.step import loss_function
from builders import toy_frame
from conftest import TINY_GRID, as_float64, random_variables, tiny


def frames(n=6, extra_points=0):
    out = []
    for i in range(n):
        f = toy_frame(np.random.default_rng(i), TINY_GRID)
        if extra_points and i == 1:  # one crowded frame sets the budget
            more = np.tile(f.points[:1], (extra_points, 1))
            more[:, :2] = np.random.default_rng(9).uniform([0, -8], [16, 8], (extra_points, 2))
            f = dataclasses.replace(f, points=np.concatenate([f.points, more]))
        out.append(f)
    return out


def test_budget_is_the_most_points_rounded_up_and_capped():
    fs = frames(extra_points=150)
    most = max(len(f.points) for f in fs)  # 56 + 150
    assert pillar_budget(fs, 2048, step=64) == 256 > most
    assert pillar_budget(fs, 200, step=64) == 200  # never above max_pillars
    assert pillar_budget(frames(), 2048, step=128) == 128  # at least one step
    assert pillar_budget([], 2048) == 128
    with pytest.raises(ValueError, match="max_pillars=0"):
        pillar_budget(fs, 0)


def test_no_window_or_augmentation_loses_a_pillar_and_the_kept_slots_are_unchanged():
    fs = frames(extra_points=150)
    budget = pillar_budget(fs, 4096, step=64)
    windows = training_windows(TINY_GRID, 20)
    full = [PillarSpec(g, tiny("dsfec_s").config.point_features, 4096, 4) for g in windows]
    small = [dataclasses.replace(s, max_pillars=budget) for s in full]
    targets = zoo.family_of("dsfec_s").points.targets(tiny("dsfec_s").config)
    a, b = (BatchStream(fs, specs, targets, batch_size=3, seed=5) for specs in (full, small))
    for step in range(8):  # every window, augmented batches
        x, y = a.batch(step), b.batch(step)
        assert all(s["dropped_pillar_limit"] == 0 for s in y["stats"]) and x["stats"] == y["stats"]
        for key in ("points", "mask", "coords"):
            np.testing.assert_array_equal(x["inputs"][key][:, :budget], y["inputs"][key])
        assert not x["inputs"]["mask"][:, budget:].any() and (x["inputs"]["coords"][:, budget:] == -1).all()


@pytest.mark.parametrize("name", ["baseline"])  # PointPillars' masked batch norm; FEC has no cross-slot term
def test_loss_and_gradients_equal_those_with_every_slot(name, float64):
    fs = frames()
    budget = pillar_budget(fs, 1024, step=64)
    # the slots meet only the encoder (masked batch norm) and the scatter; one block per stage and
    # one conv per head keep every kind of layer after the scatter, with fewer of each to compile
    small_net = dict(stage_blocks=(1, 1, 1, 1), head_convs=1)
    big, small = tiny(name, max_pillars=1024, **small_net), tiny(name, max_pillars=budget, **small_net)
    targets = zoo.family_of(name).points.targets(big.config)
    batches = [as_float64(BatchStream(fs, PillarSpec.of(d.config), targets, batch_size=2, seed=1).batch(0))
               for d in (big, small)]
    variables = as_float64(random_variables(big, 0))  # from eval_shape: `init` would compile (~10 s)
    results = []
    for det, batch in zip((big, small), batches):
        grad = jax.value_and_grad(loss_function(det), has_aux=True)
        (loss, (_, stats)), g = jax.jit(grad)(variables["params"], variables["batch_stats"],
                                              {"inputs": batch["inputs"], "targets": batch["targets"]})
        results.append((loss, g, stats))
    (l1, g1, s1), (l2, g2, s2) = results
    assert jax.tree.leaves(g1)[0].dtype == jnp.float64 and float(l1) == pytest.approx(float(l2), rel=1e-12)
    num = sum(float(jnp.sum((a - b) ** 2)) for a, b in zip(jax.tree.leaves(g1), jax.tree.leaves(g2)))
    den = sum(float(jnp.sum(a ** 2)) for a in jax.tree.leaves(g1))
    assert den > 0 and (num / den) ** 0.5 < 1e-9
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12), s1, s2)

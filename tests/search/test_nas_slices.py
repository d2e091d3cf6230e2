"""The DSFEC width x depth x stem supernet (search/nas/slices.py, spos_points.py): a subnet taken
out of it is its stand-alone network, its masks come from a look-up table, its train step leaves
the idle blocks alone, and it starts from the base's leading channels."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from dsfec_jax import zoo
from dsfec_jax.train.warm_start import LeadingSlices, warm_start
from search.nas import slices
from search.nas.spaces import get_space
from search.nas.spos_points import PointSubnetInputs, PointSupernet
from search.recipes import get_recipe
from conftest import random_fill


@pytest.fixture(scope="module")
def supernet():
    space = get_space("dsfec")
    grid = get_recipe("smoke", space.base).model_overrides()  # an 8 m grid: small compiles
    sup = zoo.create(space.base, **space.overrides(space.largest()), **grid)
    shapes = jax.eval_shape(lambda: sup.init(jax.random.key(0)))
    v = {c: random_fill(shapes[c], seed=1, scale_range=(0.5, 1.5)) for c in ("params", "batch_stats")}
    return space, grid, PointSupernet(sup), v, PointSubnetInputs(space)


def _rel(a, b) -> float:
    return max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y))) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_subnet_equals_its_standalone_network(supernet):
    space, grid, det, v, inputs = supernet
    run = jax.jit(lambda v, x: det.apply(v, x))
    run_train = jax.jit(lambda v, x: det.apply(v, x, train=True)[0])
    x = det.supernet.dummy_inputs(2, seed=3)
    genes = space.encode({"stem_filters": 12, "stage1_width": 0.75, "stage2_width": 0.5, "stage3_width": 1.0,
                          "stage4_width": 0.5, "stage1_blocks": 1, "stage2_blocks": 3, "stage3_blocks": 2,
                          "stage4_blocks": 1})
    sub = zoo.create(space.base, **space.overrides(genes), **grid)
    sub_vars = slices.extract(v, sub)
    assert sub.config.stage_blocks == (1, 3, 2, 1) and sub.config.fec_filters[-1] == 12
    assert _rel(run(v, {**x, **inputs(genes)}), sub.apply(sub_vars, x)) < 2e-5  # running statistics
    assert _rel(run_train(v, {**x, **inputs(genes)}), sub.apply(sub_vars, x, train=True)[0]) < 2e-5  # batch statistics
    wider = inputs(space.largest())  # the same subnet without its masks is another network
    assert _rel(run(v, {**x, **wider, "depth": inputs(genes)["depth"]}), sub.apply(sub_vars, x)) > 1e-3


def test_mask_table_gives_each_subnets_widths(supernet):
    space, grid, _, _, inputs = supernet
    assert {space.choices[i].name for i, _ in inputs.table.control.values()} == {
        "stem_filters", "stage1_width", "stage2_width", "stage3_width", "stage4_width"}
    for seed in (1, 2):
        genes = space.sample(np.random.default_rng(seed))
        exact = slices.widths_of(zoo.create(space.base, **space.overrides(genes), **grid))
        fast = inputs(genes)
        for path, mask in fast["masks"].items():
            p = tuple(path.split("/"))
            if p in exact:  # modules of blocks past the subnet's depth are idle
                assert mask.sum() == exact[p] and mask[:exact[p]].all()
        assert list(fast["depth"]) == list(space.overrides(genes)["stage_blocks"])


def test_train_step_moves_only_the_subnets_blocks(supernet):
    space, grid, det, v, inputs = supernet
    from dsfec_jax.data.batches import collate
    from dsfec_jax.data.points.pillarize import PillarSpec
    from dsfec_jax.data.points.sources import load_frames

    family, cfg = zoo.family_of(space.base), det.config
    frames = load_frames("synthetic", "train", 2, seed=0, features=family.points.input_columns)
    batch = collate(frames, PillarSpec.of(cfg), family.points.targets(cfg), family.points.origin_input)
    tx = optax.adamw(1e-3, weight_decay=0.1)
    genes = space.encode({**space.decode(space.largest()), "stage2_blocks": 1, "stage3_blocks": 2})
    state = {"params": v["params"], "batch_stats": v["batch_stats"], "opt_state": tx.init(v["params"]),
             "step": jnp.zeros((), jnp.int32)}
    before = jax.tree.map(np.asarray, state)
    new, _ = det.make_train_step(tx)(state, {"inputs": {**batch["inputs"], **inputs(genes)}, "targets": batch["targets"]})
    moved = lambda k: not all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(before["params"][k]),
                                                                  jax.tree.leaves(new["params"][k])))
    assert moved("stage2_block0") and moved("stage3_block1") and moved("stage4_block2")
    assert not moved("stage2_block1") and not moved("stage2_block2") and not moved("stage3_block2")


def test_leading_slices_seed_other_widths():
    fresh = {"params": {"a": {"kernel": np.zeros((3, 3, 4, 8), np.float32)}, "b": {"kernel": np.zeros((2, 2))}},
             "batch_stats": {"a": {"mean": np.zeros(8, np.float32)}}}
    trained = {"params": {"a": {"kernel": np.ones((3, 3, 6, 5), np.float32)}, "b": {"kernel": np.ones((2, 2))}},
               "batch_stats": {"a": {"mean": np.ones(5, np.float32)}}}
    merged, how = warm_start(fresh, LeadingSlices(trained))
    k = merged["params"]["a"]["kernel"]
    assert how == {"copied": ["b"], "sliced": ["a"], "fresh": []}
    assert k[:, :, :4, :5].min() == 1 and k[..., 5:].max() == 0 and k.shape == (3, 3, 4, 8)
    assert list(merged["batch_stats"]["a"]["mean"]) == [1] * 5 + [0] * 3
    assert warm_start(fresh, trained)[1]["fresh"] == ["a"]  # a plain source copies equal shapes only

"""The weight-sharing supernet with elastic widths: a subnet taken out of it is its stand-alone network."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.train.parallel import PER_STEP_INPUTS
from search.nas import elastic
from search.nas.spaces import get_space
from builders import assert_rows_are_the_batch_rows
from conftest import random_fill


@pytest.fixture(scope="module")
def supernet():
    space = get_space("yolov8n_adapter")
    sup = elastic.supernet_of(space)
    shapes = jax.eval_shape(lambda: sup.init(jax.random.key(0)))
    # trained-like stand-in weights: alpha, gamma and every BN away from their initial values
    v = {c: random_fill(shapes[c], seed=1, scale_range=(0.5, 1.5)) for c in ("params", "batch_stats")}
    v["nas"] = jax.tree.map(lambda s: jnp.int32(1), shapes["nas"])
    for k in range(7):  # Exchangers that matter: alpha 1 (the residual's weight), gamma 1
        v["params"]["adapter"][f"exchangers_{k}"].update(alpha=jnp.float32(1), gamma=jnp.float32(1))
    run = jax.jit(lambda v, x, m: elastic.masked_apply(sup, v, x, m))
    run_train = jax.jit(lambda v, x, m: elastic.masked_apply(sup, v, x, m, train=True)[0])
    return space, sup, v, run, run_train


def _rel(a, b) -> float:
    return max(float(jnp.max(jnp.abs(x - y)) / jnp.max(jnp.abs(y))) for x, y in zip(a, b))


@pytest.mark.parametrize("seed", [0])
def test_subnet_equals_its_standalone_network(supernet, seed):
    space, sup, v, run, run_train = supernet
    genes = space.sample(np.random.default_rng(seed))
    sub = zoo.create(space.base, **space.overrides(genes))
    masks = elastic.masks(sup, sub)
    chosen = elastic.with_fusions(v, space.overrides(genes)["fusion"])
    sub_vars = elastic.extract(sup, chosen, sub)
    x = sup.dummy_inputs(2, seed=3)
    sub_run = jax.jit(lambda v, x: sub.apply(v, x))
    sub_train = jax.jit(lambda v, x: sub.apply(v, x, train=True)[0])
    assert _rel(run(chosen, x, masks), sub_run(sub_vars, x)) < 2e-5  # running statistics
    assert _rel(run_train(chosen, x, masks), sub_train(sub_vars, x)) < 2e-5  # batch statistics
    other = tuple(2 if f == 1 else 1 for f in space.overrides(genes)["fusion"])  # every Exchanger's option changed
    assert _rel(run(elastic.with_fusions(v, other), x, masks), sub_run(sub_vars, x)) > 1e-4  # 10x the tolerance above


def test_one_compile_serves_every_subnet_and_idle_weights_get_no_gradient(supernet):
    space, sup, v, _, _ = supernet
    x = sup.dummy_inputs(1, seed=4)
    traces = []

    def loss(params, nas, masks):
        traces.append(1)
        out = elastic.masked_apply(sup, {**v, "params": params, "nas": nas}, x, masks)
        return sum(jnp.sum(o ** 2) for o in out)

    grad = jax.jit(jax.grad(loss))
    smallest = zoo.create(space.base, **space.overrides(space.smallest()))
    for genes in (space.smallest(), space.largest()):
        sub = zoo.create(space.base, **space.overrides(genes))
        chosen = elastic.with_fusions(v, space.overrides(genes)["fusion"])
        g = grad(v["params"], chosen["nas"], elastic.masks(sup, sub))
    assert len(traces) == 1
    g = grad(v["params"], elastic.with_fusions(v, (1,) * 7)["nas"], elastic.masks(sup, smallest))
    kernel = np.asarray(g["backbone"]["layer3"]["conv"]["kernel"])  # block 3 at 1/4: 16 of 64 outputs kept
    assert np.abs(kernel[..., 16:]).max() == 0 and np.abs(kernel[..., :16]).max() > 0
    assert np.asarray(g["adapter"]["exchangers_0"]["fusion_weight"]) == 0  # option 1 chosen: option 3's weight idle


def test_mask_table_and_spos_draws(supernet):
    from search.nas.spos import SPOSStream, SubnetInputs

    space, sup, _, _, _ = supernet
    subnet_inputs = SubnetInputs(space, sup)
    for seed in (5, 6):  # the look-up table gives exactly the traced masks
        genes = space.sample(np.random.default_rng(seed))
        exact = elastic.masks(sup, zoo.create(space.base, **space.overrides(genes)))
        fast = subnet_inputs(genes)
        assert fast["masks"].keys() == exact.keys()
        assert all(np.array_equal(fast["masks"][k], np.asarray(exact[k])) for k in exact)
        assert [int(e["fusion"]) for e in fast["nas"]["adapter"].values()] == list(space.overrides(genes)["fusion"])

    class Batches:  # a stand-in stream: SPOSStream only adds the subnet to its batches
        batch_size = 2

        def batch(self, s, rows=slice(None)):
            return {"inputs": {"heat": np.full((2,), s)[rows]}, "targets": {}, "window": 0}

    a, b = SPOSStream(Batches(), space, subnet_inputs, seed=0), SPOSStream(Batches(), space, subnet_inputs, seed=1)
    draws = [a.genes(s) for s in range(6)]
    assert draws == [a.genes(s) for s in range(6)] and len(set(draws)) == 6  # a pure function of (seed, step)
    assert draws != [b.genes(s) for s in range(6)]
    batch = a.batch(3)
    assert batch["inputs"]["heat"][0] == 3 and batch["window"] == 0
    assert batch.keys() == {"inputs", "targets", "window", PER_STEP_INPUTS} and batch[PER_STEP_INPUTS] == ("masks", "nas")
    assert_rows_are_the_batch_rows(a, 3, slice(1, 2))  # a process's row, with the whole subnet
    assert all(np.array_equal(batch["inputs"]["masks"][k], v) for k, v in subnet_inputs(a.genes(3))["masks"].items())
    assert a.batch_size == 2


def test_param_shapes_are_cached_per_config_and_equal_a_fresh_trace(monkeypatch):
    """The mask table's shape look-ups trace each config once: a second network of the same config
    is a cache hit (no init traced), another config or float64 mode is traced anew."""
    space = get_space("yolov8n_adapter")
    traced = []
    real = elastic._traced_shapes
    monkeypatch.setattr(elastic, "_traced_shapes", lambda det: traced.append(det.config) or real(det))
    monkeypatch.setattr(elastic, "_PARAM_SHAPES", {})
    small = space.overrides(space.smallest())
    first = elastic.param_shapes(zoo.create(space.base, **small))
    again = elastic.param_shapes(zoo.create(space.base, **small))
    assert len(traced) == 1 and again is first
    fresh = jax.eval_shape(lambda: zoo.create(space.base, **small).init(jax.random.key(0)))["params"]
    assert jax.tree.structure(first) == jax.tree.structure(fresh)
    assert jax.tree.leaves(jax.tree.map(lambda a, b: a.shape == b.shape and a.dtype == b.dtype, first, fresh)) == \
        [True] * len(jax.tree.leaves(fresh))
    elastic.param_shapes(zoo.create(space.base, **space.overrides(space.largest())))
    assert len(traced) == 2  # another config: traced

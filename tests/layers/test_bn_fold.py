"""BatchNorm folded into the conv before it (layers/bn_fold.py, zoo.deploy): every family's inference
form equals its trained network on random, non-trivial BN statistics, no BN is left to run, and a
conv whose output something else reads too keeps its BN."""

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import random_fill, random_variables, tiny
from dsfec_jax import zoo
from dsfec_jax.layers import bn_fold
from dsfec_jax.layers.conv import Conv, ConvTranspose, DepthwiseConv, batch_norm

# the smallest variant of each family with its kinds of conv -> BN: DSFEC's depthwise, pillar and
# transposed convs; YOLOv10n's C2f, depthwise convs and attention (the YOLO-RD family's blocks but
# YOLOv9's RepConvN, whose wiring Tangle below has); Shuffle-YOLOv3's shuffle units (RadarNeXt:
# tests/models/test_radarnext.py, after its MobileOne re-parameterization). Small inputs: the plan
# is found on the config's own input size and holds at any.
FAMILIES = {"dsfec_s": None, "yolov10n": (64, 32), "shuffle_yolov3": (64, 64)}


def detector_and_inputs(name):
    hw = FAMILIES[name]
    if hw is None:
        det = tiny(name)
        return det, det.dummy_inputs(1)
    det = zoo.create(name)
    return det, det.config.dummy_inputs(1, hw=hw)


@pytest.mark.parametrize("name", FAMILIES)
def test_folded_detector_equals_the_trained_one_with_no_batch_norm_left(name):
    det, inputs = detector_and_inputs(name)
    variables = random_variables(det, 3)
    folded_det, folded = zoo.deploy(det, variables)
    bns = [p for p, _ in jax.tree_util.tree_flatten_with_path(variables["batch_stats"])[0] if p[-1].key == "mean"]
    assert len(folded_det.plan.folds) == len(bns) > 0  # every BN of these families follows a conv
    assert jax.tree.leaves(folded["batch_stats"]) == []
    assert not any(p[-1].key == "scale" for p, _ in jax.tree_util.tree_flatten_with_path(folded["params"])[0])
    want = jax.jit(det.apply)(variables, inputs)
    lowered = jax.jit(folded_det.apply).lower(folded, inputs)
    assert "rsqrt" not in lowered.as_text()  # no BN normalises anything in the compiled program
    got = lowered.compile()(folded, inputs)
    for (path, w), g in zip(jax.tree_util.tree_flatten_with_path(want)[0], jax.tree.leaves(got)):
        scale = float(jnp.abs(w).max())
        assert scale > 1e-3, f"{name}{jax.tree_util.keystr(path)} is all zeros"
        np.testing.assert_allclose(g, w, rtol=1e-4, atol=1e-5 * scale, err_msg=f"{name}{jax.tree_util.keystr(path)}")


class Tangle(nn.Module):
    """conv a -> BN and conv a1 -> BN on the same input, summed (RepConvN: both foldable); conv
    b -> BN, and b's output added after (not foldable); one conv module called twice, each call's
    output through its own BN (shared weights: not foldable); a depthwise and a transposed conv
    -> BN (foldable)."""

    @nn.compact
    def __call__(self, x, train: bool = False):
        a = batch_norm(train, "bn_a")(Conv(8, 3, name="conv_a")(x))
        a = a + batch_norm(train, "bn_a1")(Conv(8, 1, name="conv_a1")(x))
        b_raw = Conv(8, 3, use_bias=True, name="conv_b")(x)
        b = batch_norm(train, "bn_b")(b_raw) + b_raw
        shared = Conv(8, 1, name="shared")
        c = batch_norm(train, "bn_c1")(shared(a)) + batch_norm(train, "bn_c2")(shared(b))
        d = batch_norm(train, "bn_d")(DepthwiseConv(3, name="dw")(c))
        return batch_norm(train, "bn_e")(ConvTranspose(4, 3, 2, name="up")(d))


def test_a_conv_read_twice_or_called_twice_keeps_its_batch_norm():
    net, x = Tangle(), jnp.asarray(np.random.default_rng(0).normal(size=(2, 8, 8, 3)), jnp.float32)
    variables = random_fill(jax.eval_shape(lambda: net.init(jax.random.key(0), x)), 5)
    call = lambda v, x: net.apply(v, x)  # noqa: E731
    plan = bn_fold.find_folds(call, variables, x)
    assert [(f.conv, f.bn, f.conv_has_bias) for f in plan.folds] == [
        (("conv_a",), ("bn_a",), False), (("conv_a1",), ("bn_a1",), False), (("dw",), ("bn_d",), False),
        (("up",), ("bn_e",), True)]
    folded = bn_fold.folded_variables(variables, plan)
    assert sorted(folded["batch_stats"]) == ["bn_b", "bn_c1", "bn_c2"]
    np.testing.assert_allclose(bn_fold.folded_call(call, plan)(folded, x), call(variables, x), rtol=1e-4, atol=1e-5)


def test_a_folded_detector_refuses_training_and_deploys_as_it_is():
    det = tiny("dsfec_s")
    folded_det, folded = zoo.deploy(det, random_variables(det, 0))
    assert zoo.deploy(folded_det, folded) == (folded_det, folded)
    with pytest.raises(ValueError, match="evaluation only"):
        folded_det.apply(folded, det.dummy_inputs(1), train=True)

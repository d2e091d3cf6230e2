"""ShuffleNetV2 units and Darknet-53 blocks: the channel shuffle against torchvision's reshape,
the split conventions, shapes and parameter counts, stride 2, and the residual add."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.layers.darknet import DarknetResidual, DarknetStage
from dsfec_jax.layers.shufflenet import ShuffleUnit, channel_shuffle, split_channels


def n_params(variables) -> int:
    return sum(int(np.prod(a.shape)) for a in jax.tree_util.tree_leaves(variables["params"]))


def torch_channel_shuffle(x_nchw: np.ndarray, groups: int) -> np.ndarray:
    """torchvision.models.shufflenetv2.channel_shuffle in numpy (NCHW)."""
    b, c, h, w = x_nchw.shape
    x = x_nchw.reshape(b, groups, c // groups, h, w).transpose(0, 2, 1, 3, 4)
    return x.reshape(b, c, h, w)


@pytest.mark.parametrize("c", [2, 8, 12])
def test_channel_shuffle_interleaves_the_halves_as_torchvision(c):
    x = np.random.default_rng(0).normal(size=(2, 3, 4, c)).astype(np.float32)
    y = np.asarray(channel_shuffle(jnp.asarray(x), 2))
    ref = torch_channel_shuffle(x.transpose(0, 3, 1, 2), 2).transpose(0, 2, 3, 1)
    np.testing.assert_array_equal(y, ref)
    # a permutation that interleaves the halves: out[2j] = in[j], out[2j + 1] = in[C/2 + j]
    perm = np.asarray(channel_shuffle(jnp.arange(c)[None], 2))[0]
    assert sorted(perm) == list(range(c))
    np.testing.assert_array_equal(perm[0::2], np.arange(c // 2))
    np.testing.assert_array_equal(perm[1::2], np.arange(c // 2, c))


def test_split_conventions():
    x = jnp.arange(8.0)[None, None, None]
    a, b = split_channels(x, "chunk")
    np.testing.assert_array_equal(a[0, 0, 0], [0, 1, 2, 3])
    np.testing.assert_array_equal(b[0, 0, 0], [4, 5, 6, 7])
    a, b = split_channels(x, "even_odd")
    np.testing.assert_array_equal(a[0, 0, 0], [0, 2, 4, 6])
    np.testing.assert_array_equal(b[0, 0, 0], [1, 3, 5, 7])
    with pytest.raises(ValueError, match="split"):
        split_channels(x, "halves")


def unit_params(cin: int, c: int, k: int, stride: int) -> int:
    """Weights + BN scale/offset of a unit with `c` outputs: branch 1x1, dw kxk, 1x1 (+ the stride-2
    left branch dw kxk on C_in and 1x1)."""
    h = c // 2
    main = (cin if stride == 2 else h) * h + 2 * h + k * k * h + 2 * h + h * h + 2 * h
    proj = k * k * cin + 2 * cin + cin * h + 2 * h if stride == 2 else 0
    return main + proj


@pytest.mark.parametrize("split", ["chunk", "even_odd"])
@pytest.mark.parametrize("kernel,act", [(3, "relu"), (5, "hard_swish")])
def test_stride1_unit_keeps_shape_and_passes_half_through(split, kernel, act):
    x = jax.random.normal(jax.random.key(1), (2, 8, 8, 16))
    unit = ShuffleUnit(16, 1, kernel, act, split)
    variables = unit.init(jax.random.key(0), x)
    y = unit.apply(variables, x)
    assert y.shape == x.shape
    assert n_params(variables) == unit_params(16, 16, kernel, 1)
    assert variables["params"]["main_dw"]["kernel"].shape == (kernel, kernel, 1, 8)
    if split == "chunk":  # undo the shuffle: [kept half, branch]
        kept = y.reshape(2, 8, 8, 8, 2)[..., 0]
        np.testing.assert_array_equal(kept, x[..., :8])
    else:  # megvii: no shuffle after the concat, the kept half is the even channels
        np.testing.assert_array_equal(y[..., :8], x[..., 0::2])


@pytest.mark.parametrize("kernel", [3, 5])
def test_stride2_unit_doubles_channels_and_halves_hw(kernel):
    x = jax.random.normal(jax.random.key(1), (1, 16, 12, 8))
    unit = ShuffleUnit(16, 2, kernel, "relu")
    variables = unit.init(jax.random.key(0), x)
    assert unit.apply(variables, x).shape == (1, 8, 6, 16)
    assert n_params(variables) == unit_params(8, 16, kernel, 2)


def test_depthwise_impls_agree_in_a_stride2_unit():
    x = jax.random.normal(jax.random.key(1), (1, 16, 16, 8))
    shifted = ShuffleUnit(16, 2, 5, "hard_swish", depthwise_impl="shifted")
    variables = shifted.init(jax.random.key(0), x)
    grouped = ShuffleUnit(16, 2, 5, "hard_swish", depthwise_impl="grouped")
    np.testing.assert_allclose(shifted.apply(variables, x), grouped.apply(variables, x), atol=1e-5)


def test_unit_rejects_bad_widths():
    x = jnp.zeros((1, 8, 8, 16))
    with pytest.raises(ValueError, match="keeps its width"):
        ShuffleUnit(32, 1).init(jax.random.key(0), x)
    with pytest.raises(ValueError, match="even"):
        ShuffleUnit(15, 2).init(jax.random.key(0), x)


def test_darknet_residual_adds_its_input():
    x = jax.random.normal(jax.random.key(1), (1, 8, 8, 16))
    block = DarknetResidual(16)
    variables = block.init(jax.random.key(0), x)
    # 1x1 16 -> 8 and 3x3 8 -> 16, each with BN scale/offset
    assert n_params(variables) == 16 * 8 + 2 * 8 + 9 * 8 * 16 + 2 * 16
    zeroed = jax.tree_util.tree_map_with_path(
        lambda p, a: jnp.zeros_like(a) if "conv2" in str(p) and p[-1].key in ("scale", "bias") else a, variables)
    np.testing.assert_array_equal(block.apply(zeroed, x), x)  # the branch is 0: the shortcut alone


def test_darknet_stage_downsamples_then_keeps_shape():
    x = jnp.zeros((1, 16, 16, 8))
    stage = DarknetStage(16, 2)
    variables = jax.eval_shape(stage.init, jax.random.key(0), x)
    assert jax.eval_shape(stage.apply, variables, x).shape == (1, 8, 8, 16)
    assert n_params(variables) == 9 * 8 * 16 + 2 * 16 + 2 * (16 * 8 + 2 * 8 + 9 * 8 * 16 + 2 * 16)

"""Strided convs of thin inputs over blocks of pixels (layers/conv_space_to_depth.py): the same
numbers as XLA's conv for the kernels, strides and paddings a stem uses (and odd ones), only for a
strided conv of at most THIN_INPUT channels to at most YNNPACK_MIN_WIDTH, and the runtime form of a
network computes its stem so."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import random_variables
from dsfec_jax import zoo
from dsfec_jax.layers import conv, conv_space_to_depth

CASES = [  # (h, w, k, stride, pads, input channels, output channels)
    (256, 64, 3, 2, ((1, 1), (1, 1)), 3, 16),  # the RD YOLOs' stem: padded to 32 outputs for YNNPACK
    (9, 14, 3, 2, (conv.same_pads(9, 3, 2), conv.same_pads(14, 3, 2)), 3, 24),  # TF 'SAME', odd sizes
    (10, 12, 5, 2, ((2, 2), (2, 2)), 1, 8),
    (11, 13, 7, 2, ((3, 3), (3, 3)), 3, 64),
    (16, 16, 4, 4, ((0, 0), (0, 0)), 3, 16),  # kernel = stride: one block tap
    (15, 17, 3, 3, ((1, 1), (0, 2)), 2, 5),  # stride 3, uneven pads
    (7, 9, 3, 2, ((0, 0), (0, 0)), 3, 16),  # no padding: the last block is partly past the edge
]


@pytest.mark.parametrize("h, w, k, stride, pads, cin, cout", CASES)
def test_the_block_form_equals_xlas_conv(h, w, k, stride, pads, cin, cout):
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.standard_normal((2, h, w, cin)), jnp.float32)
    kernel = jnp.asarray(rng.standard_normal((k, k, cin, cout)), jnp.float32)
    want = jax.lax.conv_general_dilated(x, kernel, (stride, stride), pads, dimension_numbers=conv.DIMS)
    got = jax.jit(conv_space_to_depth.conv_as_space_to_depth, static_argnums=(2, 3))(x, kernel, stride, pads)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * float(jnp.abs(want).max()))


def test_only_strided_convs_of_thin_inputs_take_it():
    image = jnp.zeros((1, 256, 64, 3))
    assert conv_space_to_depth.fits(image, jnp.zeros((3, 3, 3, 16)), 2)
    assert not conv_space_to_depth.fits(image, jnp.zeros((3, 3, 3, 16)), 1)  # stride 1: no blocks to form
    assert not conv_space_to_depth.fits(jnp.zeros((1, 128, 32, 16)), jnp.zeros((3, 3, 16, 32)), 2)  # wide input
    assert not conv_space_to_depth.fits(image, jnp.zeros((3, 3, 3, 24)), 2)  # 24 outputs: YNNPACK's already


def test_the_runtime_form_computes_the_stem_over_blocks_with_the_same_outputs():
    det = zoo.create("yolov8n")
    variables = random_variables(det, 3)
    inputs = jax.tree.map(lambda a: jnp.asarray(np.random.default_rng(1).random(a.shape), a.dtype),
                          det.dummy_inputs(1))  # not a constant map: the stem's taps must all matter
    runtime, folded = zoo.deploy(det, variables)
    export, folded_too = zoo.deploy(det, variables, for_export=True)
    assert "transpose" in str(jax.make_jaxpr(runtime.apply)(folded, inputs))  # the blocks' regrouping
    assert "transpose" not in str(jax.make_jaxpr(export.apply)(folded_too, inputs))
    want, got = jax.jit(export.apply)(folded_too, inputs), jax.jit(runtime.apply)(folded, inputs)
    for w, g in zip(jax.tree.leaves(want), jax.tree.leaves(got)):
        np.testing.assert_allclose(g, w, rtol=1e-4, atol=1e-5 * float(jnp.abs(w).max()))

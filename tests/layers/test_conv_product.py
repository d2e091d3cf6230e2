"""Small wide convs as one matrix product at inference (layers/conv_product.py): the same numbers as
XLA's conv for every kernel, stride and padding the zoo uses; the JAX runtime's inference form
computes them so, and the export's keeps every conv a conv."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import random_variables
from dsfec_jax import zoo
from dsfec_jax.layers import conv, conv_product

CASES = [  # (h, w, k, stride, pads)
    (8, 13, 3, 1, ((1, 1), (1, 1))),
    (9, 14, 3, 2, (conv.same_pads(9, 3, 2), conv.same_pads(14, 3, 2))),  # TF 'SAME': the extra pixel low
    (8, 12, 3, 2, ((1, 1), (1, 1))),  # PyTorch's k // 2 on a stride-2 conv
    (7, 5, 5, 1, ((2, 2), (2, 2))),
    (6, 6, 3, 1, ((0, 0), (0, 0))),
]


@pytest.mark.parametrize("h, w, k, stride, pads", CASES)
def test_the_product_equals_xlas_conv(h, w, k, stride, pads):
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.standard_normal((2, h, w, 16)), jnp.float32)
    kernel = jnp.asarray(rng.standard_normal((k, k, 16, 24)), jnp.float32)
    want = jax.lax.conv_general_dilated(x, kernel, (stride, stride), pads, dimension_numbers=conv.DIMS)
    got = conv_product.conv_as_product(x, kernel, stride, pads)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * float(jnp.abs(want).max()))


def test_only_small_wide_convs_fit():
    pads = ((1, 1), (1, 1))
    wide = jnp.zeros((3, 3, 256, 512))
    assert conv_product.fits(jnp.zeros((1, 16, 26, 256)), wide, 1, pads)  # 416 pixels
    assert not conv_product.fits(jnp.zeros((1, 32, 52, 256)), wide, 1, pads)  # 1664 pixels
    assert conv_product.fits(jnp.zeros((1, 32, 52, 256)), wide, 2, pads)  # strided to 416
    assert not conv_product.fits(jnp.zeros((1, 8, 13, 64)), jnp.zeros((3, 3, 64, 512)), 1, pads)  # narrow input


def conv_count(fn, *args) -> int:
    return str(jax.make_jaxpr(fn)(*args)).count("conv_general_dilated")


def test_the_runtime_form_computes_the_fitting_convs_as_products_and_the_export_form_does_not():
    """yolov8n at its 256 x 64 maps: the stride-16 and -32 convs are 16 x 4 and 8 x 2 pixels, 128 and
    256 channels wide."""
    det = zoo.create("yolov8n")
    variables = random_variables(det, 3)
    inputs = det.dummy_inputs(1)
    runtime, folded = zoo.deploy(det, variables)
    export, folded_too = zoo.deploy(det, variables, for_export=True)
    plain = conv_count(lambda v, x: export.apply(v, x), folded_too, inputs)
    products = conv_count(lambda v, x: runtime.apply(v, x), folded, inputs)
    assert 0 < products < plain  # some convs became products, the wide-image ones stayed
    assert zoo.deploy(runtime, folded, for_export=True)[0].conv_products is False
    want, got = jax.jit(export.apply)(folded_too, inputs), jax.jit(runtime.apply)(folded, inputs)
    for w, g in zip(jax.tree.leaves(want), jax.tree.leaves(got)):
        np.testing.assert_allclose(g, w, rtol=1e-4, atol=1e-5 * float(jnp.abs(w).max()))

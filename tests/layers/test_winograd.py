"""Winograd's F(4x4, 3x3) and its dual (layers/winograd.py) give XLA's 3x3 convolution, input
gradient and kernel gradient for any size (whole tiles or not) and any padding up to 2."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.layers import winograd
from dsfec_jax.layers.conv import plain_conv

SHAPES_PADS = [((2, 8, 8, 3), 5, ((1, 1), (1, 1))),     # whole tiles, 'SAME'
               ((2, 7, 9, 5), 6, ((1, 1), (1, 1))),     # partial tiles
               ((1, 8, 8, 3), 4, ((0, 2), (1, 1))),     # unequal pads
               ((2, 5, 11, 4), 3, ((2, 0), (0, 1))),
               ((1, 1, 1, 2), 2, ((1, 1), (1, 1)))]     # one pixel


def relative_max_error(got, want) -> float:
    return float(jnp.abs(got - want).max() / jnp.abs(want).max())


def xla_parts(x, w, pads, key):
    """XLA's output, a random output gradient g and XLA's (d x, d w) for it."""
    y, vjp = jax.vjp(lambda x, w: plain_conv(x, w, pads), x, w)
    g = jax.random.normal(key, y.shape, y.dtype)
    return y, g, *vjp(g)


@pytest.mark.parametrize("dtype,tol", [(jnp.float32, 1e-5), (jnp.float64, 1e-12)])
@pytest.mark.parametrize("shape,cout,pads", SHAPES_PADS)
def test_forward_and_both_gradients_equal_xlas(shape, cout, pads, dtype, tol, float64):
    x = jax.random.normal(jax.random.key(0), shape, dtype)
    w = jax.random.normal(jax.random.key(1), (3, 3, shape[-1], cout), dtype)
    y, g, dx, dw = xla_parts(x, w, pads, jax.random.key(2))
    # one program: eagerly, each of the transforms' many small ops would be dispatched alone
    got = jax.jit(lambda x, w, g: (winograd.conv3x3(x, w, pads), winograd.conv3x3_input_grad(g, w, pads),
                                   winograd.conv3x3_kernel_grad(x, g, pads)))(x, w, g)
    for name, a, b in zip(("y", "dx", "dw"), got, (y, dx, dw)):
        assert a.shape == b.shape and a.dtype == dtype, name
        assert relative_max_error(a, b) < tol, name


def test_the_comparison_can_fail():
    """One pixel off (the other side's padding) or the transposed dual (the filter transform of
    F(4, 3) where the output's belongs) gives a far-off gradient."""
    x = jax.random.normal(jax.random.key(3), (2, 9, 10, 4))
    w = jax.random.normal(jax.random.key(4), (3, 3, 4, 5))
    pads = ((0, 2), (1, 1))
    _, g, dx, dw = xla_parts(x, w, pads, jax.random.key(5))
    assert relative_max_error(winograd.conv3x3_kernel_grad(x, g, ((2, 0), (1, 1))), dw) > 1e-2
    assert relative_max_error(winograd.conv3x3_input_grad(g, w, ((2, 0), (1, 1))), dx) > 1e-2
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(winograd, "G", np.roll(winograd.G, 1, axis=1))
        assert relative_max_error(winograd.conv3x3_kernel_grad(x, g, pads), dw) > 1e-2


def test_the_kernel_gradient_is_36_batched_products():
    """The point of the form: one dot with the 36 transformed positions as its batch dimension."""
    x, g = jnp.ones((1, 8, 8, 4)), jnp.ones((1, 8, 8, 6))
    text = str(jax.make_jaxpr(lambda x, g: winograd.conv3x3_kernel_grad(x, g, ((1, 1), (1, 1))))(x, g))
    assert "dot_general" in text and "f32[36,4,6]" in text


@pytest.mark.parametrize("f", [winograd.F2, winograd.F4], ids=["F2", "F4"])
@pytest.mark.parametrize("shape,cout,pads", SHAPES_PADS)
def test_the_forward_from_a_transformed_kernel_equals_xlas(shape, cout, pads, f):
    """The inference form's path: the kernel transformed once in float64 (numpy), then the tiles'
    products; F2's error is a direct conv's own rounding, F4's a few times it."""
    x = jax.random.normal(jax.random.key(6), shape)
    w = jax.random.normal(jax.random.key(7), (3, 3, shape[-1], cout))
    v = winograd.transformed_kernel(w, f)
    assert v.shape == (f.span ** 2, shape[-1], cout) and v.dtype == np.float32
    got = jax.jit(lambda x: winograd.conv3x3_transformed(x, v, pads, f))(x)
    assert relative_max_error(got, plain_conv(x, w, pads)) < (2e-6 if f is winograd.F2 else 1e-5)
    assert relative_max_error(jax.jit(lambda x, w: winograd.conv3x3(x, w, pads, f))(x, w), plain_conv(x, w, pads)) < 1e-5


def test_a_wrong_f2_transform_fails_the_comparison():
    x = jax.random.normal(jax.random.key(8), (1, 6, 7, 4))
    w = jax.random.normal(jax.random.key(9), (3, 3, 4, 5))
    pads = ((1, 1), (1, 1))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(winograd, "B_T_2", np.roll(winograd.B_T_2, 1, axis=1))
        got = winograd.conv3x3_transformed(x, winograd.transformed_kernel(w, winograd.F2), pads, winograd.F2)
        assert relative_max_error(got, plain_conv(x, w, pads)) > 1e-2

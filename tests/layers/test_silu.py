"""SiLU's CPU inference form (layers/silu.py): the logistic as Eigen's rational function, within
float32 rounding of the exact SiLU, used only inside `rational_logistic()`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.layers import silu


def exact_silu(x) -> np.ndarray:
    x = np.asarray(x, np.float64)
    return x / (1 + np.exp(-x))


X = jnp.concatenate([jnp.linspace(-40.0, 40.0, 20001), jnp.array([-1e30, -18.0, 0.0, 18.0, 1e30])]).astype(jnp.float32)


def test_the_rational_logistic_is_within_float_rounding_of_the_exact_one():
    with silu.rational_logistic():
        got = np.asarray(jax.jit(lambda x: silu.silu(x))(X), np.float64)
    # float32's own rounding of x * sigmoid(x) reaches ~1e-6 at |x| ~ 16
    assert np.abs(got - exact_silu(X)).max() < 4e-6
    assert np.abs(np.asarray(silu.rational_sigmoid(X)) - 1 / (1 + np.exp(-np.asarray(X, np.float64)))).max() < 1e-6
    assert np.isfinite(got).all()


def test_silu_is_exact_outside_the_context_and_after_it():
    """Each jit is its own function: the context is read while tracing, and jax's trace cache does
    not key on it (product_call enters it inside the function it traces)."""
    exact = np.asarray(jax.nn.silu(X))
    np.testing.assert_array_equal(np.asarray(jax.jit(lambda x: silu.silu(x))(X)), exact)
    with silu.rational_logistic():
        inside = np.asarray(jax.jit(lambda x: silu.silu(x))(X))
    assert not np.array_equal(inside, exact)
    np.testing.assert_array_equal(np.asarray(jax.jit(lambda x: silu.silu(x))(X)), exact)


def test_a_wrong_coefficient_fails_the_comparison():
    with pytest.MonkeyPatch.context() as patch, silu.rational_logistic():
        patch.setattr(silu, "DENOMINATOR", silu.DENOMINATOR[:-1] + (1.0,))
        got = np.asarray(silu.silu(X), np.float64)
    assert np.abs(got - exact_silu(X)).max() > 1e-3

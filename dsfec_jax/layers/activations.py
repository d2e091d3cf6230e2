"""Activations by name, so configs and search axes can name them as strings."""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp

from .silu import silu

LEAKY_SLOPE = 0.1  # the YOLO/Darknet slope; the paper does not state one


def _mish(x):
    return x * jnp.tanh(jax.nn.softplus(x))


ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "relu": jax.nn.relu,
    "leaky_relu": lambda x: jax.nn.leaky_relu(x, LEAKY_SLOPE),
    "swish": silu,  # jax.nn.swish, with a rational logistic in the CPU inference form (layers/silu.py)
    "mish": _mish,
    "hard_swish": jax.nn.hard_swish,
    "gelu": jax.nn.gelu,
}


def activation(name: str) -> Callable[[jax.Array], jax.Array]:
    """The activation function called `name`; unknown names fail with the valid list."""
    try:
        return ACTIVATIONS[name]
    except KeyError:
        raise ValueError(f"unknown activation {name!r}; valid: {sorted(ACTIVATIONS)}") from None

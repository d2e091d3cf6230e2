"""Batch normalisation over every axis but the last, with a hand-written training gradient.

`BatchNorm` holds the variables of `flax.linen.BatchNorm` under the same names (params `scale`,
`bias`; batch_stats `mean`, `var`) and computes the same values: the batch mean and the
E[x^2] - E[x]^2 variance (clipped at 0) in training, the running averages in evaluation, and
the same running-average update. Weights move between the two unchanged.

Why a gradient of its own: autodiff of training-mode BN differentiates through the mean and the
variance separately and leaves XLA's CPU backend several full passes over the activation and a
few gradient accumulations (`add_any`) besides. The closed form needs two passes: one
reduction (sum dy, sum dy * x_hat) and one elementwise pass for dx, into which XLA fuses the
activation's backward that produces dy. The gain is small, as XLA already fuses much of
autodiff's form; its history is in docs/profiler.md, and
`dsfec bench --train --compare kernels=plain` re-measures the fast kernels against the textbook ones.
"""

from __future__ import annotations

import functools
import math

import flax.linen as nn
import jax
import jax.numpy as jnp
from jax import lax

from .kernels import Kernels, hand_written


def _reduction_axes(x) -> tuple[int, ...]:
    return tuple(range(x.ndim - 1))


def batch_stats(x, where=None):
    """(mean, variance) over every axis but the last (the positions `where` is true, if given), as
    flax computes them (fast variance)."""
    axes = _reduction_axes(x)
    mean = x.mean(axes, where=where)
    return mean, jnp.maximum(0.0, (x * x).mean(axes, where=where) - mean * mean)


def plain_batch_norm(x, scale, bias, epsilon: float, where=None):
    """Training-mode BN by autodiff's rules: (y, batch mean, batch variance)."""
    mean, var = batch_stats(x, where)
    return normalize(x, mean, var, scale, bias, epsilon), mean, var


def normalize(x, mean, var, scale, bias, epsilon: float):
    """flax's `_normalize` order of operations, so evaluation outputs match it bit for bit."""
    return (x - mean) * (lax.rsqrt(var + epsilon) * scale) + bias


@functools.partial(jax.custom_vjp, nondiff_argnums=(3,))
def fast_batch_norm(x, scale, bias, epsilon: float):
    """`plain_batch_norm` with the closed-form gradient. The mean and variance outputs feed the
    running averages only, so their cotangents are ignored (they are never differentiated)."""
    return plain_batch_norm(x, scale, bias, epsilon)


def _fast_fwd(x, scale, bias, epsilon):
    y, mean, var = plain_batch_norm(x, scale, bias, epsilon)
    return (y, mean, var), (x, scale, mean, lax.rsqrt(var + epsilon))


def _fast_bwd(epsilon, residuals, cotangents):
    x, scale, mean, inv_std = residuals
    dy = cotangents[0]
    axes, n = _reduction_axes(x), math.prod(x.shape[:-1])
    x_hat = (x - mean) * inv_std
    d_bias, d_scale = dy.sum(axes), (dy * x_hat).sum(axes)
    # d x = scale / sigma * (dy - mean(dy) - x_hat * mean(dy * x_hat)): the mean and variance
    # terms of the chain rule, folded into one pass.
    dx = (scale * inv_std) * (dy - d_bias / n - x_hat * (d_scale / n))
    return dx, d_scale, d_bias


fast_batch_norm.defvjp(_fast_fwd, _fast_bwd)


class BatchNorm(nn.Module):
    """`flax.linen.BatchNorm(axis=-1)`'s variables and values; `kernels="fast"` trains with the
    closed-form gradient (`fast_batch_norm`), "plain" with autodiff. A `mask` (training only)
    keeps the statistics to the masked-in positions, by autodiff."""

    use_running_average: bool
    momentum: float = 0.99
    epsilon: float = 1e-5
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, mask=None):
        features = (x.shape[-1],)
        ra_mean = self.variable("batch_stats", "mean", lambda s: jnp.zeros(s, jnp.float32), features)
        ra_var = self.variable("batch_stats", "var", lambda s: jnp.ones(s, jnp.float32), features)
        scale = self.param("scale", nn.initializers.ones, features, jnp.float32)
        bias = self.param("bias", nn.initializers.zeros, features, jnp.float32)
        if self.use_running_average:
            return normalize(x, ra_mean.value, ra_var.value, scale, bias, self.epsilon)
        if mask is None and hand_written(self.kernels):
            y, mean, var = fast_batch_norm(x, scale, bias, self.epsilon)
        else:
            where = None if mask is None else jnp.asarray(mask, bool)
            y, mean, var = plain_batch_norm(x, scale, bias, self.epsilon, where)
        if not self.is_initializing():
            ra_mean.value = self.momentum * ra_mean.value + (1 - self.momentum) * mean
            ra_var.value = self.momentum * ra_var.value + (1 - self.momentum) * var
        return y

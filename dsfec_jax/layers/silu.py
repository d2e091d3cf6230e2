"""SiLU (x * logistic(x)), and its CPU inference form with the logistic as a rational function.

XLA's CPU backend evaluates the logistic exactly, as 1 / (1 + exp(-x)), a sizeable share of a
small network's forward (YOLOv8n's 39 SiLUs), where ONNX Runtime's MLAS (like Eigen, whose
coefficients it uses) evaluates it as a rational function, an odd degree-9 polynomial over an even
degree-10 one on [-18, 18], with no exp and one divide. The same function in jnp runs several
times as fast (measured: docs/performance.md, `python -m experiments.bn_fold_speed --ab silu`),
with an absolute error of the order of float32's own rounding of the exact form.

`silu(x)` is what the layers call. It is exact, except while `rational_logistic()` is entered: the
JAX runtime's inference form on the CPU enters it around its network's call
(layers/conv_product.product_call), so that program is traced with the rational form. Training,
gradients and the ONNX export (whose runtime has its own Sigmoid) never are. The context is read
while tracing and jax's trace cache does not key on it: enter it inside the function you jit, as
product_call does, never around a jitted function also traced outside it.
"""

from __future__ import annotations

import contextlib
import contextvars

import jax
import jax.numpy as jnp

# Eigen's float logistic (MLAS's MlasLogisticConstants): p(x) = x * P(x^2), q(x) = Q(x^2), highest power first
NUMERATOR = (4.37031012579801e-11, 1.15627324459942e-07, 6.08574864600143e-05, 8.51377133304701e-03,
             2.48287947061529e-01)
DENOMINATOR = (6.10247389755681e-13, 5.76102136993427e-09, 6.29106785017040e-06, 1.70198817374094e-03,
               1.16817656904453e-01, 9.93151921023180e-01)
RANGE = 18.0  # |x| beyond which the logistic is 0 or 1 in float32

_RATIONAL = contextvars.ContextVar("rational_logistic", default=False)


def _polynomial(coefficients, x2):
    out = coefficients[0]
    for c in coefficients[1:]:
        out = out * x2 + c
    return out


def rational_sigmoid(x):
    """The logistic as Eigen's rational function: p(x) / q(x) + 1/2 on x clamped to [-RANGE, RANGE]."""
    x = jnp.clip(x, -RANGE, RANGE)
    x2 = x * x
    return jnp.clip(x * _polynomial(NUMERATOR, x2) / _polynomial(DENOMINATOR, x2) + 0.5, 0.0, 1.0)


def silu(x):
    """x * logistic(x): exact, or with the rational logistic inside `rational_logistic()`."""
    return x * rational_sigmoid(x) if _RATIONAL.get() else jax.nn.silu(x)


@contextlib.contextmanager
def rational_logistic():
    """Within it (while a network is traced), `silu` uses the rational logistic."""
    token = _RATIONAL.set(True)
    try:
        yield
    finally:
        _RATIONAL.reset(token)

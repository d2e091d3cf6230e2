"""Convolution primitives (NHWC) that know their own multiply-accumulate count.

Every primitive has `macs(in_shape, out_shape)`, which the profiler reads through a method
interceptor, so analytic FLOPs always describe the network that actually runs.
"""

from __future__ import annotations

import math
from typing import Literal

import flax.linen as nn
import jax.numpy as jnp
from jax import lax

DIMS = ("NHWC", "HWIO", "NHWC")
DepthwiseImpl = Literal["shifted", "grouped"]
kernel_init = nn.initializers.variance_scaling(2.0, "fan_in", "truncated_normal")


def same_pads(size: int, kernel: int, stride: int) -> tuple[int, int]:
    """TF/JAX 'SAME' padding (extra pixel at the high end), as the paper's TF model used."""
    out = -(-size // stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return total // 2, total - total // 2


class Conv(nn.Module):
    """Dense KxK convolution, optional bias."""

    features: int
    kernel: int = 3
    stride: int = 1
    use_bias: bool = False
    bias_init: nn.initializers.Initializer = nn.initializers.zeros

    @nn.compact
    def __call__(self, x_BxHxWxC):
        k, cin = self.kernel, x_BxHxWxC.shape[-1]
        w = self.param("kernel", kernel_init, (k, k, cin, self.features))
        y = lax.conv_general_dilated(
            x_BxHxWxC, w, (self.stride, self.stride), "SAME", dimension_numbers=DIMS
        )
        if self.use_bias:
            y = y + self.param("bias", self.bias_init, (self.features,))
        return y

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(out_shape[:-1]) * self.kernel**2 * in_shape[-1] * self.features


class DepthwiseConv(nn.Module):
    """Depthwise KxK convolution with one weight tensor and two kernels.

    `impl="shifted"` sums K*K shifted, strided slices (XLA on CPU runs this ~7x faster than a
    grouped conv); `impl="grouped"` is `feature_group_count=C`, which exports to ONNX as a
    single `Conv(group=C)`. Both read the same (K, K, 1, C) kernel.
    """

    kernel: int = 3
    stride: int = 1
    impl: DepthwiseImpl = "shifted"

    @nn.compact
    def __call__(self, x_BxHxWxC):
        c = x_BxHxWxC.shape[-1]
        w = self.param("kernel", kernel_init, (self.kernel, self.kernel, 1, c))
        if self.impl == "grouped":
            return lax.conv_general_dilated(
                x_BxHxWxC, w, (self.stride, self.stride), "SAME",
                dimension_numbers=DIMS, feature_group_count=c,
            )
        if self.impl == "shifted":
            return shifted_depthwise(x_BxHxWxC, w[:, :, 0, :], self.stride)
        raise ValueError(f"DepthwiseConv.impl={self.impl!r}; valid: 'shifted', 'grouped'")

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(out_shape[:-1]) * self.kernel**2 * out_shape[-1]


def shifted_depthwise(x_BxHxWxC, w_KxKxC, stride: int, pads: tuple[int, int] | None = None):
    """Depthwise conv as K*K multiply-adds of shifted views of the padded input. `pads`
    (low, high) on both axes; default TF 'SAME'."""
    k = w_KxKxC.shape[0]
    _, h, w, _ = x_BxHxWxC.shape
    ph, pw = (same_pads(h, k, stride), same_pads(w, k, stride)) if pads is None else (pads, pads)
    xp = jnp.pad(x_BxHxWxC, ((0, 0), ph, pw, (0, 0)))
    ho, wo = (h + sum(ph) - k) // stride + 1, (w + sum(pw) - k) // stride + 1
    out = None
    for i in range(k):
        for j in range(k):
            tap = xp[:, i : i + (ho - 1) * stride + 1 : stride, j : j + (wo - 1) * stride + 1 : stride, :]
            term = tap * w_KxKxC[i, j]
            out = term if out is None else out + term
    return out


class ConvTranspose(nn.Module):
    """KxK transposed convolution ('deconv') that upsamples by `stride`, bias optional (PIXOR: with)."""

    features: int
    kernel: int = 3
    stride: int = 2
    use_bias: bool = True

    @nn.compact
    def __call__(self, x_BxHxWxC):
        cin = x_BxHxWxC.shape[-1]
        w = self.param("kernel", kernel_init, (self.kernel, self.kernel, cin, self.features))
        y = lax.conv_transpose(
            x_BxHxWxC, w, (self.stride, self.stride), "SAME", dimension_numbers=DIMS
        )
        return y + self.param("bias", nn.initializers.zeros, (self.features,)) if self.use_bias else y

    def macs(self, in_shape, out_shape) -> int:
        # Each input pixel scatters a KxK patch: zero taps of the dilated form are not counted.
        return math.prod(in_shape[:-1]) * self.kernel**2 * in_shape[-1] * self.features


class PointLinear(nn.Module):
    """A 1x1 conv over points (PointPillars' per-point linear layer): (..., D) -> (..., F)."""

    features: int
    use_bias: bool = True

    @nn.compact
    def __call__(self, x):
        w = self.param("kernel", nn.initializers.lecun_normal(), (x.shape[-1], self.features))
        y = jnp.dot(x, w)
        if self.use_bias:
            y = y + self.param("bias", nn.initializers.zeros, (self.features,))
        return y

    def macs(self, in_shape, out_shape) -> int:
        return math.prod(in_shape[:-1]) * in_shape[-1] * self.features


# Keras defaults (the paper trained in TensorFlow); search's BN recalibration inverts this momentum.
BN_MOMENTUM = 0.99
BN_EPS = 1e-3


def batch_norm(train: bool, name: str | None = None) -> nn.BatchNorm:
    return nn.BatchNorm(use_running_average=not train, momentum=BN_MOMENTUM, epsilon=BN_EPS, name=name)


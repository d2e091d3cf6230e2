"""Backbone blocks: the DSFEC depthwise-separable block and the PIXOR residual bottleneck."""

from __future__ import annotations

import flax.linen as nn

from .activations import activation
from .conv import Conv, DepthwiseConv, DepthwiseImpl, Kernels, batch_norm


class ConvBNAct(nn.Module):
    """KxK conv + BN + activation (stems and head towers)."""

    features: int
    kernel: int = 3
    stride: int = 1
    act: str = "relu"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = Conv(self.features, self.kernel, self.stride, kernels=self.kernels, name="conv")(x)
        return activation(self.act)(batch_norm(train, "bn", self.kernels)(x))


class DSConv(nn.Module):
    """Depthwise-separable block: 3x3 depthwise + BN + act, 1x1 pointwise + BN + act."""

    features: int
    stride: int = 1
    act: str = "leaky_relu"
    depthwise_impl: DepthwiseImpl = "shifted"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        act = activation(self.act)
        x = DepthwiseConv(3, self.stride, self.depthwise_impl, self.kernels, name="dw")(x)
        x = act(batch_norm(train, "dw_bn", self.kernels)(x))
        x = Conv(self.features, 1, kernels=self.kernels, name="pw")(x)
        return act(batch_norm(train, "pw_bn", self.kernels)(x))


class ResidualBottleneck(nn.Module):
    """PIXOR bottleneck: 1x1 -> 3x3 (carries the stride) -> 1x1 (x4), projection shortcut."""

    features: int  # output width = 4 x bottleneck planes
    stride: int = 1
    act: str = "relu"
    expansion: int = 4
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        act = activation(self.act)
        planes, k = self.features // self.expansion, self.kernels
        y = act(batch_norm(train, "bn1", k)(Conv(planes, 1, kernels=k, name="conv1")(x)))
        y = act(batch_norm(train, "bn2", k)(Conv(planes, 3, self.stride, kernels=k, name="conv2")(y)))
        y = batch_norm(train, "bn3", k)(Conv(self.features, 1, kernels=k, name="conv3")(y))
        shortcut = x
        if self.stride != 1 or x.shape[-1] != self.features:
            shortcut = Conv(self.features, 1, self.stride, kernels=k, name="proj")(x)
            shortcut = batch_norm(train, "proj_bn", k)(shortcut)
        return act(y + shortcut)

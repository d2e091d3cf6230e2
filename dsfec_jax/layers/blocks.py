"""Backbone blocks: the DSFEC depthwise-separable block and the PIXOR residual bottleneck."""

from __future__ import annotations

import flax.linen as nn

from .activations import activation
from .conv import Conv, DepthwiseConv, DepthwiseImpl, batch_norm


class ConvBNAct(nn.Module):
    """KxK conv + BN + activation (stems and head towers)."""

    features: int
    kernel: int = 3
    stride: int = 1
    act: str = "relu"

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = Conv(self.features, self.kernel, self.stride, name="conv")(x)
        return activation(self.act)(batch_norm(train, "bn")(x))


class DSConv(nn.Module):
    """Depthwise-separable block: 3x3 depthwise + BN + act, 1x1 pointwise + BN + act."""

    features: int
    stride: int = 1
    act: str = "leaky_relu"
    depthwise_impl: DepthwiseImpl = "shifted"

    @nn.compact
    def __call__(self, x, train: bool = False):
        act = activation(self.act)
        x = DepthwiseConv(3, self.stride, self.depthwise_impl, name="dw")(x)
        x = act(batch_norm(train, "dw_bn")(x))
        x = Conv(self.features, 1, name="pw")(x)
        return act(batch_norm(train, "pw_bn")(x))


class ResidualBottleneck(nn.Module):
    """PIXOR bottleneck: 1x1 -> 3x3 (carries the stride) -> 1x1 (x4), projection shortcut."""

    features: int  # output width = 4 x bottleneck planes
    stride: int = 1
    act: str = "relu"
    expansion: int = 4

    @nn.compact
    def __call__(self, x, train: bool = False):
        act = activation(self.act)
        planes = self.features // self.expansion
        y = act(batch_norm(train, "bn1")(Conv(planes, 1, name="conv1")(x)))
        y = act(batch_norm(train, "bn2")(Conv(planes, 3, self.stride, name="conv2")(y)))
        y = batch_norm(train, "bn3")(Conv(self.features, 1, name="conv3")(y))
        shortcut = x
        if self.stride != 1 or x.shape[-1] != self.features:
            shortcut = Conv(self.features, 1, self.stride, name="proj")(x)
            shortcut = batch_norm(train, "proj_bn")(shortcut)
        return act(y + shortcut)

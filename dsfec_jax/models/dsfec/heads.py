"""Dense detection heads: a conv tower, then class logits and a box code per cell."""

from __future__ import annotations

import math

import flax.linen as nn

from ...layers import Conv, ConvBNAct, DSConv
from ...layers.conv import DepthwiseImpl, Kernels

CLS_PRIOR = 0.01  # focal-loss prior: start with ~1% foreground so the loss is not swamped


class DenseHead(nn.Module):
    """`convs` x (3x3 conv or DSConv, BN, act) of `width`, then a 3x3 output conv with bias."""

    num_classes: int
    box_code_size: int = 6
    convs: int = 4
    width: int = 96
    kind: str = "conv"  # "conv" | "dsconv"
    act: str = "swish"
    depthwise_impl: DepthwiseImpl = "shifted"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        for i in range(self.convs):
            if self.kind == "conv":
                x = ConvBNAct(self.width, 3, 1, self.act, self.kernels, name=f"tower{i}")(x, train)
            else:
                x = DSConv(self.width, 1, self.act, self.depthwise_impl, self.kernels, name=f"tower{i}")(x, train)
        prior = -math.log((1 - CLS_PRIOR) / CLS_PRIOR)
        cls = Conv(self.num_classes, 3, use_bias=True, bias_init=nn.initializers.constant(prior), kernels=self.kernels,
                   name="cls")(x)
        box = Conv(self.box_code_size, 3, use_bias=True, kernels=self.kernels, name="box")(x)
        return {"cls": cls, "box": box}

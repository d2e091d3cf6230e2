"""Darknet-53 blocks (Redmon & Farhadi, YOLOv3, 2018), NHWC.

Facts from pjreddie/darknet:cfg/yolov3-voc.cfg (the code here is ours):
- every [convolutional] with batch_normalize=1 is conv (no bias) + BN + leaky ReLU (slope 0.1,
  layers.activations.LEAKY_SLOPE); `ConvBNAct` of layers/blocks.py is that layer;
- a stage is a 3x3 stride-2 conv to the stage width ("# Downsample"), then `repeats` residual
  blocks: 1x1 conv to width / 2, 3x3 conv back to width, [shortcut] from=-3 with linear
  activation (a plain add).
Differences from darknet, kept on purpose (the house conventions): 'SAME' padding (darknet pads
size / 2 on every side, which differs only at stride 2: one pixel of offset, as layers/yolo.py
explains for PyTorch) and the house BN (layers.conv.batch_norm: momentum 0.99 as darknet's
rolling update .99 / .01; epsilon 1e-3 where darknet adds 1e-6 to the standard deviation).
"""

from __future__ import annotations

import flax.linen as nn

from .blocks import ConvBNAct
from .conv import Kernels


class DarknetResidual(nn.Module):
    """1x1 conv to features / 2, 3x3 conv to `features`, plus the input (same width)."""

    features: int
    act: str = "leaky_relu"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        if x.shape[-1] != self.features:
            raise ValueError(f"DarknetResidual: input width {x.shape[-1]} != features {self.features}")
        y = ConvBNAct(self.features // 2, 1, 1, self.act, self.kernels, name="conv1")(x, train)
        y = ConvBNAct(self.features, 3, 1, self.act, self.kernels, name="conv2")(y, train)
        return x + y


class DarknetStage(nn.Module):
    """3x3 stride-2 conv to `features` ("down"), then `repeats` DarknetResiduals ("res<i>")."""

    features: int
    repeats: int
    act: str = "leaky_relu"
    kernels: Kernels = "auto"

    @nn.compact
    def __call__(self, x, train: bool = False):
        x = ConvBNAct(self.features, 3, 2, self.act, self.kernels, name="down")(x, train)
        for i in range(self.repeats):
            x = DarknetResidual(self.features, self.act, self.kernels, name=f"res{i}")(x, train)
        return x

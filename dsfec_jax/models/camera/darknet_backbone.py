"""Darknet-53 (pjreddie/darknet:cfg/yolov3-voc.cfg layers 0-74): image (B, H, W, 3) -> the outputs
of darknet layers 36, 61 and 74 (strides 8, 16, 32; widths 256, 512, 1024), which YOLOv3's routes
and first head read.

A 3x3 stride-1 conv to `stem_width` (32, `stem`), then five stages (`stage0`..`stage4`): 3x3
stride-2 conv to widths 64/128/256/512/1024 and 1/2/8/8/4 residual blocks (layers/darknet.py).
"""

from __future__ import annotations

from typing import Any

import flax.linen as nn

from ...layers.blocks import ConvBNAct
from ...layers.darknet import DarknetStage
from .layout import STAGES

TAPS = (2, 3, 4)  # the stages at strides 8, 16, 32 (darknet layers 36, 61, 74)


class Darknet53(nn.Module):
    cfg: Any  # a CameraConfig (config.py imports the net to build it, so the net never imports config.py)

    @nn.compact
    def __call__(self, x, train: bool = False):
        c = self.cfg
        x = ConvBNAct(c.stem_width, 3, 1, c.act, c.kernels, name="stem")(x, train)
        outs = []
        for s in range(STAGES):
            x = DarknetStage(c.widths[s], c.repeats[s], c.act, c.kernels, name=f"stage{s}")(x, train)
            outs.append(x)
        return tuple(outs[i] for i in TAPS)

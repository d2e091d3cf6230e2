"""Shuffle-YOLOv3's backbone (the paper's Table 1: repeats 1-2-6-6-4, widths 64-128-192-256-384):
image (B, H, W, 3) -> the stage outputs at strides 8, 16, 32 (widths 192, 256, 384).

Stage 0 is Table 1's first "1": with `first_repeat` 'stem' a 3x3 stride-2 conv + BN + act
(`stage0`); with 'unit' a 3x3 stride-1 conv (`stem`, darknet's first layer) then repeats[0] shuffle
units. Stages 1-4 are repeats[s] ShuffleNetV2 units (`stage<s>_<i>`), the first of each with
stride 2. Each stage's kernel and activation come from `cfg.stage_style` (5x5 and h-swish in the
deep stages). config.py says why each choice.
"""

from __future__ import annotations

from typing import Any

import flax.linen as nn

from ...layers.blocks import ConvBNAct
from ...layers.shufflenet import ShuffleUnit
from .layout import STAGES

TAPS = (2, 3, 4)  # the stages at strides 8, 16, 32


class ShuffleBackbone(nn.Module):
    cfg: Any  # a CameraConfig (config.py imports the net to build it, so the net never imports config.py)

    @nn.compact
    def __call__(self, x, train: bool = False):
        c, outs = self.cfg, []
        for s in range(STAGES):
            kernel, act = c.stage_style(s)
            if s == 0 and c.first_repeat == "stem":
                x = ConvBNAct(c.widths[0], 3, 2, act, c.kernels, name="stage0")(x, train)
            else:
                if s == 0:
                    x = ConvBNAct(c.stem_width, 3, 1, act, c.kernels, name="stem")(x, train)
                for i in range(c.repeats[s]):
                    x = ShuffleUnit(c.widths[s], 2 if i == 0 else 1, kernel, act, c.split, c.depthwise_impl,
                                    c.kernels, name=f"stage{s}_{i}")(x, train)
            outs.append(x)
        return tuple(outs[i] for i in TAPS)

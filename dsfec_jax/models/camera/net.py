"""The camera YOLOv3 detector: backbone -> YOLOv3 detection layers (yolo3_neck_head.py).

image (B, H, W, 3) float32 in [0, 1], NHWC, H and W multiples of 32 -> a tuple of three raw maps
ordered by stride (8, 16, 32), each (B, H/s, W/s, num_anchors, 5 + num_classes) with the last axis
[tx, ty, tw, th, objectness logit, class logits], straight from a 1x1 conv with bias (decode and
loss live in decode.py and loss.py).

`ARCHITECTURES` maps `cfg.backbone` to (backbone module, level block of the shared head).
Variables: {'params', 'batch_stats'} with subtrees 'backbone' and 'head'.
"""

from __future__ import annotations

from typing import Any, Callable

import flax.linen as nn

from .darknet_backbone import Darknet53
from .layout import INPUT
from .shufflenet_backbone import ShuffleBackbone
from .yolo3_neck_head import YoloV3Head, darknet_level, shuffle_level

STRIDE = 32  # the largest stride

# backbone kind -> (backbone module class, fn(cfg, level, name) -> that level's head block)
ARCHITECTURES: dict[str, tuple[type[nn.Module], Callable]] = {
    "shuffle": (ShuffleBackbone, shuffle_level),
    "darknet53": (Darknet53, darknet_level),
}


class CameraNet(nn.Module):
    cfg: Any  # a CameraConfig (config.py imports this module to build the net, so it is not imported here)

    def setup(self):
        backbone, level = ARCHITECTURES[self.cfg.backbone]
        self.backbone = backbone(self.cfg)
        self.head = YoloV3Head(self.cfg, level)

    def __call__(self, image, train: bool = False):
        """Raw head maps of `image` (also accepted by keyword `image=`, as zoo.Detector passes it)."""
        if image.ndim != 4 or image.shape[-1] != 3:
            raise ValueError(f"{self.cfg.name}: {INPUT} must be (B, H, W, 3) NHWC, got {image.shape}")
        if image.shape[1] % STRIDE or image.shape[2] % STRIDE:
            raise ValueError(f"{self.cfg.name}: input {image.shape[1]}x{image.shape[2]} must be a multiple of "
                             f"{STRIDE} on both sides (letterbox / pad the image)")
        return self.head(self.backbone(image, train), train)

    # Stages for the profiler: `features`, then `head_outputs`.
    def features(self, image, train: bool = False):
        """(C3, C4, C5) of the backbone at strides 8, 16, 32."""
        return self.backbone(image, train)

    def head_outputs(self, feats, train: bool = False):
        """The raw maps (as `__call__` returns them) from the backbone's (C3, C4, C5)."""
        return self.head(feats, train)

"""The YOLOv9t (GELAN) backbone, layer for layer as ultralytics/ultralytics:
ultralytics/cfg/models/v9/yolov9t.yaml (its widths are written out: no scale multipliers).

Layers are named `layer<i>` with the YAML's indices; the `exchange(i, x) -> x` hook after every
layer is backbone.py's (the Adapter's Exchangers). The layout is YOLOv8's with GELAN blocks (two
stride-2 Convs, then a block and a downsampler per level, pyramid pooling last), so the Adapter
follows the same layers 2-8 as on YOLOv8: the seven blocks from the third one on.
"""

from __future__ import annotations

import functools

import flax.linen as nn

from ...layers.yolo import YoloConv
from ...layers.yolo_gelan import ELAN1, SPPELAN, AConv, RepNCSPELAN4
from .backbone import Backbone

# yolov9t.yaml backbone, layers 0-9: (module, args after the input width)
BACKBONE_V9T = (
    ("conv", (16, 3, 2)),  # 0 P1/2
    ("conv", (32, 3, 2)),  # 1 P2/4
    ("elan1", (32, 32, 16)),  # 2
    ("aconv", (64,)),  # 3 P3/8
    ("repncspelan4", (64, 64, 32, 3)),  # 4
    ("aconv", (96,)),  # 5 P4/16
    ("repncspelan4", (96, 96, 48, 3)),  # 6
    ("aconv", (128,)),  # 7 P5/32
    ("repncspelan4", (128, 128, 64, 3)),  # 8
    ("sppelan", (128, 64)),  # 9
)
PYRAMID_LAYERS_V9 = (4, 6, 9)  # P3, P4, P5
GELAN_MODULES = {"conv": YoloConv, "elan1": ELAN1, "aconv": AConv, "repncspelan4": RepNCSPELAN4, "sppelan": SPPELAN}


def gelan_layer(cfg, index: int) -> nn.Module:
    """yolov9t.yaml line `index` as a module (args in ultralytics' order, input width left out; the
    widths are the YAML's own, so `cfg` is not read)."""
    kind, args = BACKBONE_V9T[index]
    return GELAN_MODULES[kind](*args, name=f"layer{index}")


# Image (B, H, W, C) -> (P3, P4, P5) at strides 8, 16, 32 (64, 96, 128 channels)
GelanBackbone = functools.partial(Backbone, layer=gelan_layer, depth=len(BACKBONE_V9T), pyramid=PYRAMID_LAYERS_V9)

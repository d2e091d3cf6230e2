"""The YOLOv10n PAN neck's blocks, ultralytics yolov10n.yaml `head` layers 11-22: YOLOv8's neck with
SCDown as the second bottom-up downsampler (layer 20) and C2fCIB (shortcut, large-kernel RepVGGDW)
as the last block (layer 22); neck.py's `PanNeck` wires them. Modules carry the YAML's layer
indices; concatenation order [-1, skip]."""

from __future__ import annotations

import functools

import flax.linen as nn

from ...layers.yolo import C2f, YoloConv
from ...layers.yolo_v10 import C2fCIB, SCDown
from .neck import PanNeck


def v10_neck_stages(cfg) -> tuple[nn.Module, ...]:
    w, n = cfg.width, cfg.repeats(3)
    return (C2f(w(512), n, name="layer13"), C2f(w(256), n, name="layer16"), YoloConv(w(256), 3, 2, name="layer17"),
            C2f(w(512), n, name="layer19"), SCDown(w(512), 3, 2, name="layer20"),
            C2fCIB(w(1024), n, shortcut=True, large_kernel=True, name="layer22"))


V10Neck = functools.partial(PanNeck, stages=v10_neck_stages)

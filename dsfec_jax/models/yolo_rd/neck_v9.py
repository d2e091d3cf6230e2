"""The YOLOv9t (GELAN) PAN neck's blocks, ultralytics yolov9t.yaml `head` layers 10-21: top-down with
nearest upsampling and concatenation into RepNCSPELAN4 blocks, then bottom-up with AConv
downsamplers (neck.py's `PanNeck` wires them). Modules carry the YAML's layer indices; concatenation
order as the YAML ([-1, skip]); N3, N4, N5 have 64, 96, 128 channels."""

from __future__ import annotations

import functools

import flax.linen as nn

from ...layers.yolo_gelan import AConv, RepNCSPELAN4
from .neck import PanNeck


def gelan_neck_stages(cfg) -> tuple[nn.Module, ...]:
    """yolov9t.yaml's widths are written out (no scale multipliers), so `cfg` is not read."""
    return (RepNCSPELAN4(96, 96, 48, 3, name="layer12"), RepNCSPELAN4(64, 64, 32, 3, name="layer15"),
            AConv(48, name="layer16"), RepNCSPELAN4(96, 96, 48, 3, name="layer18"), AConv(64, name="layer19"),
            RepNCSPELAN4(128, 128, 64, 3, name="layer21"))


GelanNeck = functools.partial(PanNeck, stages=gelan_neck_stages)

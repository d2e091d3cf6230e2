"""Which backbone, neck and head each base detector (`YoloRDConfig.arch`) is built from.

- 'v8': yolov8.yaml, C2f/SPPF backbone, PAN neck, Detect (backbone.py, neck.py, head.py);
- 'v9': yolov9t.yaml, GELAN backbone and neck (RepNCSPELAN4, AConv, SPPELAN), the same Detect
  (ultralytics builds v9 with the legacy Detect head: YOLOv8's; backbone_v9.py, neck_v9.py);
- 'v10': yolov10n.yaml, SCDown/PSA backbone, C2fCIB neck, v10Detect with its one-to-many and
  one-to-one heads (backbone_v10.py, neck_v10.py, head_v10.py).
Every backbone takes the same `exchange` hook, so the Adapter attaches to each unchanged.
"""

from __future__ import annotations

from .backbone import YoloBackbone
from .backbone_v9 import GelanBackbone
from .backbone_v10 import V10Backbone
from .head import DetectHead
from .head_v10 import V10DetectHead
from .neck import YoloNeck
from .neck_v9 import GelanNeck
from .neck_v10 import V10Neck

PARTS = {
    "v8": (YoloBackbone, YoloNeck, DetectHead),
    "v9": (GelanBackbone, GelanNeck, DetectHead),
    "v10": (V10Backbone, V10Neck, V10DetectHead),
}


def build_parts(cfg):
    """(backbone, neck, head) modules of `cfg.arch`, unbound (the caller names them)."""
    backbone, neck, head = PARTS[cfg.arch]
    elastic = {"width_ratios": tuple(cfg.neck_width_ratios), "full_ch0": cfg.width(256)} if cfg.elastic else {}
    return backbone(cfg), neck(cfg), head(cfg.num_classes, cfg.reg_max, cfg.strides, cfg.box_bias, **elastic)

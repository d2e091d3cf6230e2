"""The named camera detectors as data (20 VOC classes): Shuffle-YOLOv3 (the paper's Table 1, every
open layout choice a field with its reason in config.py) and the Darknet53-YOLOv3 baseline at the
standard layout of pjreddie/darknet:cfg/yolov3-voc.cfg."""

from __future__ import annotations

from .config import CameraConfig

SHUFFLE_NOTE = ("Layout ours where the paper's Figs. 3-4 are missing: first '1' = 3x3 s2 stem conv to 64, "
                "stages 2-6-6-4 open with a stride-2 unit, YOLO layers 1x1 + 3 shuffle units at 192/256/384, "
                "concat FPN, 5x5 + h-swish in the stride-16/32 stages and all YOLO layers (see config.py)")

VARIANTS: dict[str, CameraConfig] = {
    "shuffle_yolov3": CameraConfig(name="shuffle_yolov3", notes=SHUFFLE_NOTE),
    "yolov3_darknet53": CameraConfig(
        name="yolov3_darknet53", backbone="darknet53", widths=(64, 128, 256, 512, 1024), repeats=(1, 2, 8, 8, 4),
        stem_width=32, act="leaky_relu", head_widths=(256, 512, 1024),
        notes="pjreddie/darknet cfg/yolov3-voc.cfg: Darknet-53 (1-2-8-8-4 residual blocks), leaky 0.1, "
              "three heads of five convs + 3x3 + 1x1 to 3 (5 + C), upsample + route concat"),
}

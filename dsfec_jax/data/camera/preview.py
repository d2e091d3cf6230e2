"""A camera image with its ground truth (class colours, difficult ones dashed) and predictions
(magenta), as a PNG: what `dsfec predict --png-dir` writes for camera models."""

from __future__ import annotations

from pathlib import Path

from ...boxes.boxes2d import Boxes2D
from ...core import atomic
from ...core.png import png_bytes
from .images import CameraImage
from .street.preview import CLASS_COLORS, OTHER_CLASS, outline

PREDICTION = (255, 0, 255)


def save_camera_png(item: CameraImage, path, predicted: Boxes2D | None = None) -> Path:
    img = item.image.copy()
    for xyxy, name, difficult in zip(item.boxes.xyxy, item.boxes.names, item.difficult):
        outline(img, xyxy, CLASS_COLORS.get(str(name), OTHER_CLASS), bool(difficult))
    for xyxy in ([] if predicted is None else predicted.xyxy):
        outline(img, xyxy, PREDICTION)
    path = Path(path)
    atomic.write_bytes(path, png_bytes(img))
    return path

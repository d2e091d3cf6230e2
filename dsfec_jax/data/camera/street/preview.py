"""A picture of a street frame: the image with its boxes | the depth map | the right image.

Boxes are outlined in their class colour (CLASS_COLORS); difficult ones dashed. Depth is drawn
with viridis on a log scale from DEPTH_RANGE_M[0] (yellow) to DEPTH_RANGE_M[1] (purple); the sky
(depth inf) is dark grey. Without a right image the third panel is left out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ....core import atomic
from ....core.png import png_bytes
from ...rd.colormaps import colormap_table
from .frame import StreetFrame

CLASS_COLORS = {"car": (60, 220, 90), "truck": (250, 160, 30), "bus": (255, 80, 60),
                "pedestrian": (40, 220, 240), "cyclist": (250, 230, 40)}
OTHER_CLASS = (220, 220, 220)
DEPTH_RANGE_M = (1.0, 200.0)
SKY = (20, 20, 24)
GAP = 6


def outline(img: np.ndarray, xyxy, color, dashed: bool = False) -> None:
    """Draws the pixel-edge box (x1, y1, x2, y2) one pixel wide inside its edges."""
    h, w = img.shape[:2]
    x1, y1, x2, y2 = (int(round(v)) for v in xyxy)
    x1, y1 = min(max(x1, 0), w - 1), min(max(y1, 0), h - 1)  # a box flat on the far edge stays drawable
    x2, y2 = min(max(x2 - 1, x1), w - 1), min(max(y2 - 1, y1), h - 1)
    cols, rows = np.arange(x1, x2 + 1), np.arange(y1, y2 + 1)
    if dashed:
        cols, rows = cols[(cols - x1) % 4 < 2], rows[(rows - y1) % 4 < 2]
    img[y1, cols] = img[y2, cols] = color
    img[rows, x1] = img[rows, x2] = color


def depth_panel(depth: np.ndarray) -> np.ndarray:
    lo, hi = np.log(DEPTH_RANGE_M[0]), np.log(DEPTH_RANGE_M[1])
    finite = np.isfinite(depth)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.clip((hi - np.log(np.where(finite, depth, 1.0))) / (hi - lo), 0, 1)
    img = colormap_table("viridis")[np.rint(v * 255).astype(np.int64)]
    img[~finite] = SKY
    return img


def render_street(frame: StreetFrame) -> np.ndarray:
    left = frame.image.copy()
    for xyxy, name, difficult in zip(frame.boxes.xyxy, frame.boxes.names, frame.boxes.difficult):
        outline(left, xyxy, CLASS_COLORS.get(str(name), OTHER_CLASS), bool(difficult))
    panels = [left, depth_panel(frame.depth)] + ([frame.right] if frame.right is not None else [])
    gap = np.full((left.shape[0], GAP, 3), 12, np.uint8)
    out = [panels[0]]
    for p in panels[1:]:
        out += [gap, p]
    return np.concatenate(out, 1)


def save_street_png(frame: StreetFrame, path) -> Path:
    path = Path(path)
    atomic.write_bytes(path, png_bytes(render_street(frame)))
    return path

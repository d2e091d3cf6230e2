"""Training targets for dense heads (DSFEC's Car / Truck / VRU) at the neck's resolution.

A cell is positive for a box when its centre lies inside the box's BEV footprint; the cell that
holds the box centre is always positive, so small objects (pedestrians at 1 m cells) are never
without a positive. A cell inside several boxes belongs to the box whose centre is nearest.
"""

from __future__ import annotations

import numpy as np

from ...boxes import pixor
from ...boxes.geometry import points_in_boxes
from ...boxes.structures import Boxes


def head_targets(boxes: Boxes, classes: tuple[str, ...], grid, stride: int) -> dict:
    """{'cls': (H, W, C) float32 one-hot, 'box': (H, W, 6) PIXOR code, 'reg_mask': (H, W) bool}."""
    centres = pixor.cell_centres(grid, stride)
    h, w, _ = centres.shape
    cls = np.zeros((h, w, len(classes)), np.float32)
    box = np.zeros((h, w, len(pixor.CODE)), np.float32)
    reg = np.zeros((h, w), bool)
    keep = np.isin(boxes.names, classes)
    if not keep.any():
        return {"cls": cls, "box": box, "reg_mask": reg}
    b = boxes.select(keep)
    flat = centres.reshape(-1, 2)
    cell_pts = np.concatenate([flat, np.zeros((len(flat), 1))], 1)
    z0 = np.zeros((len(b), 3))
    z0[:, :2] = b.center[:, :2]
    size = np.concatenate([b.size[:, :2], np.ones((len(b), 1))], 1)
    inside = points_in_boxes(cell_pts, z0, size, b.yaw)  # (cells, boxes), BEV only
    step = grid.cell * stride
    ci = np.floor((b.center[:, 0] - grid.x_range[0]) / step).astype(int)
    cj = np.floor((b.center[:, 1] - grid.y_range[0]) / step).astype(int)
    on_map = (ci >= 0) & (ci < h) & (cj >= 0) & (cj < w)
    inside[(ci * w + cj)[on_map], np.nonzero(on_map)[0]] = True
    dist = np.linalg.norm(flat[:, None, :] - b.center[None, :, :2], axis=-1)
    dist = np.where(inside, dist, np.inf)
    owner = dist.argmin(axis=1)
    pos = np.isfinite(dist.min(axis=1))
    cells = np.nonzero(pos)[0]
    owners = owner[cells]
    label = np.array([classes.index(n) for n in b.names])
    cls.reshape(-1, len(classes))[cells, label[owners]] = 1.0
    box.reshape(-1, 6)[cells] = pixor.encode(b.center[owners, :2], b.size[owners, :2], b.yaw[owners], flat[cells])
    reg.reshape(-1)[cells] = True
    return {"cls": cls, "box": box, "reg_mask": reg}


def detector_targets(boxes: Boxes, head_classes: dict[str, tuple[str, ...]], grid, stride: int) -> dict:
    """Targets for every head: {head name: head_targets(...)}."""
    return {name: head_targets(boxes, tuple(classes), grid, stride) for name, classes in head_classes.items()}

"""Training targets for dense heads (DSFEC's Car / Truck / VRU) at the neck's resolution.

A cell is positive for a box when its centre lies inside the box's BEV footprint; the cell that
holds the box centre is always positive, so small objects (pedestrians at 1 m cells) are never
without a positive. A cell inside several boxes belongs to the box whose centre is nearest.
"""

from __future__ import annotations

import numpy as np

from ...boxes import pixor
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
    cells, owners = cell_owners(flat, b, grid, stride, (h, w))
    label = np.array([classes.index(n) for n in b.names])
    cls.reshape(-1, len(classes))[cells, label[owners]] = 1.0
    box.reshape(-1, 6)[cells] = pixor.encode(b.center[owners, :2], b.size[owners, :2], b.yaw[owners], flat[cells])
    reg.reshape(-1)[cells] = True
    return {"cls": cls, "box": box, "reg_mask": reg}


def cell_owners(flat_xy, b: Boxes, grid, stride: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(positive cells, owning box of each) of a head map whose cell centres are `flat_xy`.

    Only the cells of each box's axis-aligned bounds (one cell of slack) are tested, not every
    cell against every box: the test and the distances are the same float64 expressions as
    `points_in_boxes` and `np.linalg.norm`, so the result equals the all-pairs one exactly
    (tests/models/test_dsfec_targets.py holds the two equal)."""
    h, w = shape
    step = grid.cell * stride
    centre = b.center[:, :2].astype(np.float64)
    c, s = np.cos(b.yaw), np.sin(b.yaw)
    half_l, half_w = b.size[:, 1] / 2, b.size[:, 0] / 2
    reach_x = np.abs(half_l * c) + np.abs(half_w * s)  # half extents of the rotated footprint
    reach_y = np.abs(half_l * s) + np.abs(half_w * c)
    lo_i = np.clip(np.floor((centre[:, 0] - reach_x - grid.x_range[0]) / step - 0.5).astype(int) - 1, 0, h)
    hi_i = np.clip(np.ceil((centre[:, 0] + reach_x - grid.x_range[0]) / step - 0.5).astype(int) + 1, -1, h - 1)
    lo_j = np.clip(np.floor((centre[:, 1] - reach_y - grid.y_range[0]) / step - 0.5).astype(int) - 1, 0, w)
    hi_j = np.clip(np.ceil((centre[:, 1] + reach_y - grid.y_range[0]) / step - 0.5).astype(int) + 1, -1, w - 1)
    n_i, n_j = np.maximum(hi_i - lo_i + 1, 0), np.maximum(hi_j - lo_j + 1, 0)
    counts = n_i * n_j
    pair_box = np.repeat(np.arange(len(b)), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    pair_cell = (lo_i[pair_box] + k // n_j[pair_box]) * w + lo_j[pair_box] + k % n_j[pair_box]
    d = flat_xy[pair_cell] - centre[pair_box]
    along = d[:, 0] * c[pair_box] + d[:, 1] * s[pair_box]
    across = -d[:, 0] * s[pair_box] + d[:, 1] * c[pair_box]
    size = b.size.astype(np.float64)
    inside = (np.abs(along) <= size[pair_box, 1] / 2) & (np.abs(across) <= size[pair_box, 0] / 2)
    pair_cell, pair_box = pair_cell[inside], pair_box[inside]
    # the cell holding a box's centre is always positive for it
    ci = np.floor((b.center[:, 0] - grid.x_range[0]) / step).astype(int)
    cj = np.floor((b.center[:, 1] - grid.y_range[0]) / step).astype(int)
    on_map = np.nonzero((ci >= 0) & (ci < h) & (cj >= 0) & (cj < w))[0]
    pair_cell = np.concatenate([pair_cell, (ci * w + cj)[on_map]])
    pair_box = np.concatenate([pair_box, on_map])
    # a cell inside several boxes belongs to the nearest centre (the lower index on a tie)
    dx, dy = flat_xy[pair_cell, 0] - b.center[pair_box, 0], flat_xy[pair_cell, 1] - b.center[pair_box, 1]
    order = np.lexsort((pair_box, np.sqrt(dx * dx + dy * dy), pair_cell))
    pair_cell, pair_box = pair_cell[order], pair_box[order]
    first = np.ones(len(order), bool)
    first[1:] = pair_cell[1:] != pair_cell[:-1]
    return pair_cell[first], pair_box[first]


def detector_targets(boxes: Boxes, head_classes: dict[str, tuple[str, ...]], grid, stride: int) -> dict:
    """Targets for every head: {head name: head_targets(...)}."""
    return {name: head_targets(boxes, tuple(classes), grid, stride) for name, classes in head_classes.items()}

"""Heatmap targets of a CenterPoint-style head (RadarNeXt's CenterHead).

Each object draws a Gaussian on its class's heatmap at the cell of its centre; overlapping
Gaussians combine by maximum. The radius is CenterPoint's `gaussian_radius` (the smallest of the
three corner-shift cases of CornerNet, each r = (b + sqrt(b^2 - 4ac)) / 2, as mmdet3d computes
it) of the box's size in feature cells at min_overlap 0.1, floored to an int and at least 2;
sigma = (2r + 1) / 6. Facts from the public RadarNeXt code (github Pay246-git468/RadarNeXt, commit
72676df, an MMDetection3D 1.4 fork: projects/RadarNeXt/radarnext/radarnext_head.py and mmdet3d's
gaussian_radius); the code is ours.
"""

from __future__ import annotations

import math

import numpy as np

MIN_OVERLAP = 0.1
MIN_RADIUS = 2


def gaussian_radius(length_cells: float, width_cells: float, min_overlap: float = MIN_OVERLAP) -> float:
    """The CenterPoint radius (float) for a box of this size in feature cells."""
    h, w = length_cells, width_cells
    cases = (
        (1.0, h + w, w * h * (1 - min_overlap) / (1 + min_overlap)),
        (4.0, 2 * (h + w), (1 - min_overlap) * w * h),
        (4 * min_overlap, -2 * min_overlap * (h + w), (min_overlap - 1) * w * h),
    )
    return min((b + math.sqrt(b * b - 4 * a * c)) / 2 for a, b, c in cases)


def heatmap_radius(length_cells: float, width_cells: float, min_overlap: float = MIN_OVERLAP) -> int:
    return max(MIN_RADIUS, int(gaussian_radius(length_cells, width_cells, min_overlap)))


def gaussian_kernel(radius: int) -> np.ndarray:
    """(2r+1, 2r+1) Gaussian with sigma = (2r+1)/6, peak 1; values below float eps * peak are 0."""
    sigma = (2 * radius + 1) / 6
    y, x = np.ogrid[-radius:radius + 1, -radius:radius + 1]
    g = np.exp(-(x * x + y * y) / (2 * sigma * sigma))
    g[g < np.finfo(g.dtype).eps * g.max()] = 0
    return g.astype(np.float32)


def draw_gaussian(heatmap_HxW: np.ndarray, row: int, col: int, radius: int) -> np.ndarray:
    """Max-combine a Gaussian of `radius` centred at (row, col) into the heatmap, in place,
    clipped at the map's edges."""
    h, w = heatmap_HxW.shape
    if not (0 <= row < h and 0 <= col < w):
        raise ValueError(f"draw_gaussian: centre cell ({row}, {col}) is outside the {h}x{w} heatmap")
    g = gaussian_kernel(radius)
    top, bottom = min(row, radius), min(h - row, radius + 1)
    left, right = min(col, radius), min(w - col, radius + 1)
    window = heatmap_HxW[row - top:row + bottom, col - left:col + right]
    np.maximum(window, g[radius - top:radius + bottom, radius - left:radius + right], out=window)
    return heatmap_HxW


MAX_OBJECTS = 128  # regression slots per frame; further objects keep their heatmap peak only
BOX_TARGET = ("dx", "dy", "z", "log_w", "log_l", "log_h", "sin_yaw", "cos_yaw")


def center_head_targets(boxes, classes: tuple[str, ...], grid, stride: int, max_objects: int = MAX_OBJECTS) -> dict:
    """CenterHead training targets of one frame at `stride` grid cells per map cell.

    hm (H, W, C) class Gaussians; corner_hm (H, W, 1) Gaussians of half the radius at each box's
    centre and its 4 edge midpoints; per regression slot k < max_objects: ind (flat cell index
    i * W + j), mask, box (8: sub-cell offset, centre z, log sizes, sin/cos yaw) and gt_box
    (x, y, z, w, l, h, yaw) for the IoU terms; origin, the grid's (x_min, y_min), so one compiled
    loss serves every training window. Rows of the map run along x, columns along y."""
    nx, ny = grid.shape
    h, w = nx // stride, ny // stride
    step = grid.cell * stride
    out = {"hm": np.zeros((h, w, len(classes)), np.float32), "corner_hm": np.zeros((h, w, 1), np.float32),
           "ind": np.zeros(max_objects, np.int32), "mask": np.zeros(max_objects, bool),
           "box": np.zeros((max_objects, len(BOX_TARGET)), np.float32), "gt_box": np.zeros((max_objects, 7), np.float32),
           "origin": np.array([grid.x_range[0], grid.y_range[0]], np.float32)}
    k = 0
    for n in range(len(boxes.names)):
        if boxes.names[n] not in classes:
            continue
        fx = (boxes.center[n, 0] - grid.x_range[0]) / step
        fy = (boxes.center[n, 1] - grid.y_range[0]) / step
        i, j = int(np.floor(fx)), int(np.floor(fy))
        if not (0 <= i < h and 0 <= j < w):
            continue
        bw, bl, bh = (float(v) for v in boxes.size[n])
        yaw = float(boxes.yaw[n])
        radius = heatmap_radius(bl / step, bw / step)
        draw_gaussian(out["hm"][:, :, classes.index(boxes.names[n])], i, j, radius)
        _draw_corners(out["corner_hm"][:, :, 0], fx, fy, bw / step, bl / step, yaw, max(radius // 2, 1))
        if k < max_objects:
            out["ind"][k], out["mask"][k] = i * w + j, True
            out["box"][k] = [fx - i, fy - j, boxes.center[n, 2], np.log(bw), np.log(bl), np.log(bh),
                             np.sin(yaw), np.cos(yaw)]
            out["gt_box"][k] = [*boxes.center[n], bw, bl, bh, yaw]
            k += 1
    return out


def _draw_corners(heatmap_HxW, fx: float, fy: float, w_cells: float, l_cells: float, yaw: float, radius: int):
    """The box centre and its 4 edge midpoints (front/back along the heading, left/right across)."""
    c, s = np.cos(yaw), np.sin(yaw)
    h, w = heatmap_HxW.shape
    for along, across in ((0, 0), (0.5, 0), (-0.5, 0), (0, 0.5), (0, -0.5)):
        px = fx + along * l_cells * c - across * w_cells * s
        py = fy + along * l_cells * s + across * w_cells * c
        i, j = int(np.floor(px)), int(np.floor(py))
        if 0 <= i < h and 0 <= j < w:
            draw_gaussian(heatmap_HxW, i, j, radius)

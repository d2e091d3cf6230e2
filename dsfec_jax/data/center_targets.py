"""Heatmap targets of a CenterPoint-style head (RadarNeXt's CenterHead).

Each object draws a Gaussian on its class's heatmap at the cell of its centre; overlapping
Gaussians combine by maximum. The radius is CenterPoint's `gaussian_radius` (the smallest of the
three corner-shift cases of CornerNet, each r = (b + sqrt(b^2 - 4ac)) / 2, as mmdet3d computes
it) of the box's size in feature cells at min_overlap 0.1, floored to an int and at least 2;
sigma = (2r + 1) / 6. Facts from ../shared/docs/reference-spec.md §1; the code is ours.
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

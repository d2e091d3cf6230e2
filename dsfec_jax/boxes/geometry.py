"""Box geometry on numpy arrays: corners and point-in-box tests."""

from __future__ import annotations

import numpy as np


def bev_corners(center_xy, size_wl, yaw) -> np.ndarray:
    """(M, 4, 2) BEV corners, counter-clockwise, of boxes with (w, l) and l along the heading."""
    center_xy, size_wl, yaw = np.asarray(center_xy), np.asarray(size_wl), np.asarray(yaw)
    half_l, half_w = size_wl[:, 1] / 2, size_wl[:, 0] / 2
    local = np.stack([np.stack([half_l, half_w], -1), np.stack([-half_l, half_w], -1),
                      np.stack([-half_l, -half_w], -1), np.stack([half_l, -half_w], -1)], 1)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = local[..., 0] * c - local[..., 1] * s
    y = local[..., 0] * s + local[..., 1] * c
    return np.stack([x, y], -1) + center_xy[:, None, :]


def points_in_boxes(points_xyz, center, size, yaw) -> np.ndarray:
    """(N, M) bool: point n lies inside box m (closed bounds, size = (w, l, h), centre z)."""
    points_xyz = np.asarray(points_xyz, np.float64)
    d = points_xyz[:, None, :] - np.asarray(center, np.float64)[None]
    c, s = np.cos(yaw)[None], np.sin(yaw)[None]
    along = d[..., 0] * c + d[..., 1] * s      # coordinate along the heading (length)
    across = -d[..., 0] * s + d[..., 1] * c    # across it (width)
    size = np.asarray(size, np.float64)
    return ((np.abs(along) <= size[None, :, 1] / 2) & (np.abs(across) <= size[None, :, 0] / 2)
            & (np.abs(d[..., 2]) <= size[None, :, 2] / 2))


def box_point_counts(points_xyz, center, size, yaw, margin_xy: float = 0.0, margin_z: float = 0.0) -> np.ndarray:
    """(M,) number of points inside each box grown by a margin on every side.

    Margins are per side (the box grows by 2 * margin along each axis): label boxes are drawn
    tight around the object while radar returns scatter a few decimetres around its surface,
    so "has >= 1 radar point" counts are taken with a small tolerance (e.g. 0.2 m xy, 0.5 m z).
    """
    size = np.asarray(size, np.float64) + 2.0 * np.array([margin_xy, margin_xy, margin_z])
    return points_in_boxes(points_xyz, center, size, yaw).sum(axis=0)

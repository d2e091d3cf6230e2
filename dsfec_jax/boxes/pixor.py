"""The PIXOR box code: (cos yaw, sin yaw, dx, dy, log w, log l) relative to a cell centre.

dx, dy are metres from the cell centre to the box centre; w, l in metres. Works on numpy and
jax.numpy arrays alike (`xp`), so decoding can run inside a jitted predictor.
"""

from __future__ import annotations

import numpy as np

CODE = ("cos", "sin", "dx", "dy", "log_w", "log_l")
MIN_SIZE = 1e-3  # metres: log of a zero-size box would be -inf


def encode(center_xy, size_wl, yaw, cell_xy, xp=np):
    """Boxes (..., 2), (..., 2), (...) and their cells' centres (..., 2) -> codes (..., 6)."""
    d = center_xy - cell_xy
    size = xp.maximum(size_wl, MIN_SIZE)
    return xp.stack([xp.cos(yaw), xp.sin(yaw), d[..., 0], d[..., 1], xp.log(size[..., 0]), xp.log(size[..., 1])], -1)


def decode(code, cell_xy, xp=np):
    """Codes (..., 6) at cells (..., 2) -> (center_xy (..., 2), size_wl (..., 2), yaw (...))."""
    yaw = xp.arctan2(code[..., 1], code[..., 0])
    center = cell_xy + code[..., 2:4]
    size = xp.exp(code[..., 4:6])
    return center, size, yaw


def cell_centres(grid, stride: int, xp=np):
    """(nx/stride, ny/stride, 2) metric centres of the cells of a head map."""
    nx, ny = grid.shape
    step = grid.cell * stride
    xs = grid.x_range[0] + (xp.arange(nx // stride) + 0.5) * step
    ys = grid.y_range[0] + (xp.arange(ny // stride) + 0.5) * step
    gx, gy = xp.meshgrid(xs, ys, indexing="ij")
    return xp.stack([gx, gy], -1)

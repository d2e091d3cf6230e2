"""Frame augmentation for training: flip across the x axis, global rotation and scaling, point
dropout. Boxes (centres, sizes, yaw, velocities) move with the points, and so do the velocity
columns of the points."""

from __future__ import annotations

import dataclasses

import numpy as np

from .frame import Boxes, Frame

VELOCITY_PAIRS = (("vx_comp", "vy_comp"), ("vx", "vy"))


@dataclasses.dataclass(frozen=True)
class AugmentConfig:
    flip_prob: float = 0.5
    rotation: float = np.pi / 8   # max |angle| in radians, uniform
    scale: tuple[float, float] = (0.95, 1.05)
    point_dropout: float = 0.1    # probability of dropping each point


def wrap_angle(a):
    """Angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _velocity_columns(frame: Frame) -> list[tuple[int, int]]:
    names = frame.point_features
    return [(names.index(a), names.index(b)) for a, b in VELOCITY_PAIRS if a in names and b in names]


def _linear(frame: Frame, matrix: np.ndarray, yaw_fn, size_scale: float) -> Frame:
    """Apply a 2x2 map to x, y (points, box centres, velocities); z scales with the sizes."""
    pts = frame.points.copy()
    pts[:, :2] = pts[:, :2] @ matrix.T
    pts[:, 2] *= size_scale
    for i, j in _velocity_columns(frame):
        pts[:, [i, j]] = pts[:, [i, j]] @ matrix.T
    b = frame.boxes
    center = b.center.copy()
    center[:, :2] = center[:, :2] @ matrix.T
    center[:, 2] *= size_scale
    boxes = Boxes(center.astype(np.float32), (b.size * size_scale).astype(np.float32),
                  wrap_angle(yaw_fn(b.yaw)).astype(np.float32), (b.velocity @ matrix.T).astype(np.float32), b.names)
    return dataclasses.replace(frame, points=pts.astype(np.float32), boxes=boxes)


def flip_y(frame: Frame) -> Frame:
    """Mirror across the x axis: y -> -y, yaw -> -yaw."""
    return _linear(frame, np.diag([1.0, -1.0]), lambda yaw: -yaw, 1.0)


def rotate(frame: Frame, angle: float) -> Frame:
    c, s = np.cos(angle), np.sin(angle)
    return _linear(frame, np.array([[c, -s], [s, c]]), lambda yaw: yaw + angle, 1.0)


def scale(frame: Frame, factor: float) -> Frame:
    return _linear(frame, np.eye(2) * factor, lambda yaw: yaw, factor)


def drop_points(frame: Frame, prob: float, rng: np.random.Generator) -> Frame:
    keep = rng.random(len(frame.points)) >= prob
    return dataclasses.replace(frame, points=frame.points[keep])


def augment(frame: Frame, cfg: AugmentConfig, rng: np.random.Generator) -> Frame:
    if rng.random() < cfg.flip_prob:
        frame = flip_y(frame)
    frame = rotate(frame, rng.uniform(-cfg.rotation, cfg.rotation))
    frame = scale(frame, rng.uniform(*cfg.scale))
    return drop_points(frame, cfg.point_dropout, rng)

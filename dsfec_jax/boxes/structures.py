"""Oriented 3D boxes with velocity and class name: what detectors output and datasets label.

Conventions: size = (w, l, h) with l along the heading (nuScenes); yaw = rotation about +z from
+x, in radians; centre z is the box centre (not its bottom, as KITTI labels store it).
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Boxes:
    center: np.ndarray    # (M, 3) float32
    size: np.ndarray      # (M, 3) float32, (w, l, h)
    yaw: np.ndarray       # (M,) float32
    velocity: np.ndarray  # (M, 2) float32, (vx, vy); zeros where unknown
    names: np.ndarray     # (M,) str, class names ('car', 'truck', 'pedestrian', 'bicycle', ...)

    def __post_init__(self):
        m = len(self.names)
        for field, shape in (("center", (m, 3)), ("size", (m, 3)), ("yaw", (m,)), ("velocity", (m, 2))):
            if np.shape(getattr(self, field)) != shape:
                raise ValueError(f"Boxes.{field} has shape {np.shape(getattr(self, field))}; expected {shape}")

    def __len__(self) -> int:
        return len(self.names)

    @classmethod
    def empty(cls) -> "Boxes":
        z = np.zeros
        return cls(z((0, 3), np.float32), z((0, 3), np.float32), z((0,), np.float32), z((0, 2), np.float32),
                   np.zeros((0,), dtype="<U16"))

    def select(self, keep) -> "Boxes":
        return Boxes(self.center[keep], self.size[keep], self.yaw[keep], self.velocity[keep], self.names[keep])

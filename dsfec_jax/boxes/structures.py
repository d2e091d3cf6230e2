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
    # (M,) int, lidar + radar points inside each ground-truth box (the nuScenes devkit's num_pts,
    # which drops boxes with 0); -1 where unknown; None when the source has no counts (synthetic)
    num_pts: np.ndarray | None = None

    def __post_init__(self):
        m = len(self.names)
        for field, shape in (("center", (m, 3)), ("size", (m, 3)), ("yaw", (m,)), ("velocity", (m, 2))):
            if np.shape(getattr(self, field)) != shape:
                raise ValueError(f"Boxes.{field} has shape {np.shape(getattr(self, field))}; expected {shape}")
        if self.num_pts is not None and np.shape(self.num_pts) != (m,):
            raise ValueError(f"Boxes.num_pts has shape {np.shape(self.num_pts)}; expected {(m,)} or None")

    def __len__(self) -> int:
        return len(self.names)

    @classmethod
    def empty(cls) -> "Boxes":
        z = np.zeros
        return cls(z((0, 3), np.float32), z((0, 3), np.float32), z((0,), np.float32), z((0, 2), np.float32),
                   np.zeros((0,), dtype="<U16"))

    def select(self, keep) -> "Boxes":
        # every field is per box: optional ones (None) stay None
        return dataclasses.replace(self, **{f.name: getattr(self, f.name)[keep] for f in dataclasses.fields(self)
                                            if getattr(self, f.name) is not None})

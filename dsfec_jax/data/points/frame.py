"""One frame schema for every source (synthetic, nuScenes, View-of-Delft, TJ4DRadSet, ...).

Models and metrics only see this: points with named feature columns, and boxes with centre,
size, yaw, velocity and class name, all in the sensor/ego frame the grid is defined in.
Conventions: size = (w, l, h) with l along the heading (nuScenes); yaw = rotation about +z from
+x, in radians; centre z is the box centre (not its bottom, as KITTI labels store it).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...boxes.structures import Boxes


@dataclasses.dataclass(frozen=True)
class Frame:
    points: np.ndarray                # (N, F) float32
    point_features: tuple[str, ...]   # F column names, x, y, z first
    boxes: Boxes
    frame_id: str = ""
    source: str = ""                  # 'synthetic', 'nuscenes', 'vod', 'tj4d', ...
    meta: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.points.ndim != 2 or self.points.shape[1] != len(self.point_features):
            raise ValueError(f"Frame {self.frame_id!r}: points shape {self.points.shape} does not match "
                             f"{len(self.point_features)} feature names {self.point_features}")
        if tuple(self.point_features[:3]) != ("x", "y", "z"):
            raise ValueError(f"Frame {self.frame_id!r}: point_features must start with x, y, z; got {self.point_features}")

    def column(self, name: str) -> np.ndarray:
        try:
            return self.points[:, self.point_features.index(name)]
        except ValueError:
            raise KeyError(f"Frame {self.frame_id!r} has no point feature {name!r}; has {self.point_features}") from None

"""One street frame: what the detector trains on (image, boxes, classes, difficult flags) and what
issue 25 scores depth and map placement with (depth map, right image, 3D ground truth, GPS).

Conventions:
- image / right: (H, W, 3) uint8 RGB. The right camera sits `baseline_m` to the right of the left
  one, same intrinsics and orientation (a rectified pair): a point at depth Z appears
  fx B / Z pixels further left in the right image.
- boxes: boxes2d.Boxes2D, (x1, y1, x2, y2) pixel edges of the visible extent, class names, and
  `difficult` flags (config.py's rules).
- depth: (H, W) float32 metres along the optical axis of the left camera (z, not the ray length);
  sky pixels (no surface) hold +inf, so `np.isfinite(depth)` is the valid mask.
- instances: (H, W) int32, the id of the object seen at each pixel (kept or dropped), -1 for road,
  clutter and sky. The box of object k is exactly the extent of instances == objects.id[k].
- objects: aligned with the boxes: id (stable across the frames of a drive), 3D box centre in the
  camera frame (x right, y down, z forward) and in ENU, size (width, length, height), compass
  heading, visible fraction, truncation.
- ego: the exact camera pose at this frame; gps: the 1 Hz fixes (geo.py).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ....boxes.boxes2d import Boxes2D
from .camera import PinholeCamera
from .geo import EgoPose, GpsTrack


@dataclasses.dataclass(frozen=True)
class StreetObjects:
    id: np.ndarray                 # (K,) int32
    center_cam: np.ndarray         # (K, 3) float64
    center_enu: np.ndarray         # (K, 3) float64
    size: np.ndarray               # (K, 3) float32 width, length, height
    heading: np.ndarray            # (K,) float64 compass rad
    visible_fraction: np.ndarray   # (K,) float32
    truncation: np.ndarray         # (K,) float32

    def __len__(self) -> int:
        return len(self.id)

    @classmethod
    def empty(cls) -> "StreetObjects":
        return cls(np.zeros(0, np.int32), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), np.float32),
                   np.zeros(0), np.zeros(0, np.float32), np.zeros(0, np.float32))

    def arrays(self, prefix: str = "obj_") -> dict[str, np.ndarray]:
        return {f"{prefix}{f.name}": getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_arrays(cls, z, prefix: str = "obj_") -> "StreetObjects":
        return cls(*(np.asarray(z[f"{prefix}{f.name}"]) for f in dataclasses.fields(cls)))


@dataclasses.dataclass(frozen=True)
class StreetFrame:
    image: np.ndarray
    boxes: Boxes2D
    objects: StreetObjects
    depth: np.ndarray
    instances: np.ndarray
    right: np.ndarray | None
    camera: PinholeCamera
    baseline_m: float
    ego: EgoPose
    gps: GpsTrack
    frame_id: str = ""
    meta: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        h, w = self.camera.height, self.camera.width
        if self.image.shape != (h, w, 3) or self.image.dtype != np.uint8:
            raise ValueError(f"StreetFrame {self.frame_id!r}: image {self.image.shape} {self.image.dtype}; "
                             f"expected ({h}, {w}, 3) uint8")
        if self.depth.shape != (h, w) or self.instances.shape != (h, w):
            raise ValueError(f"StreetFrame {self.frame_id!r}: depth {self.depth.shape} and instances "
                             f"{self.instances.shape} must be ({h}, {w})")
        if self.right is not None and self.right.shape != self.image.shape:
            raise ValueError(f"StreetFrame {self.frame_id!r}: right image {self.right.shape} != {self.image.shape}")
        if len(self.objects) != len(self.boxes) or self.boxes.difficult is None:
            raise ValueError(f"StreetFrame {self.frame_id!r}: {len(self.objects)} objects for {len(self.boxes)} "
                             f"boxes, which must carry difficult flags")
        if len(self.boxes):
            xyxy = self.boxes.xyxy
            if xyxy.min() < 0 or np.any(xyxy[:, 2] > w) or np.any(xyxy[:, 3] > h):
                raise ValueError(f"StreetFrame {self.frame_id!r}: boxes must lie inside the {w} x {h} image")

    @property
    def difficult(self) -> np.ndarray:
        return self.boxes.difficult

    def disparity(self) -> np.ndarray:
        """(H, W) float32 pixels of the left-to-right disparity fx B / depth (0 for the sky)."""
        return (self.camera.fx * self.baseline_m / self.depth).astype(np.float32)

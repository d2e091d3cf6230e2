"""The pinhole camera, its presets, and where it sits on the ego car.

Image coordinates are continuous with pixel *edges* at integers, the convention of
boxes/boxes2d.py: pixel (row i, column j) covers [j, j + 1) x [i, i + 1) and its centre is
(j + 0.5, i + 0.5). A camera-frame point (x right, y down, z forward along the optical axis)
projects to u = cx + fx x / z, v = cy + fy y / z in these coordinates.

Presets:
- 'paper': the paper's dashcam, 1920 x 1080 with a 120 deg horizontal field of view
  (shuffle_yolov3_edge.txt §4.3; reference-spec §2 FLAGs that its f = 1012 does not match the FOV):
  fx = fy = 960 / tan(60 deg) = 554.26 px, principal point at the image centre (960, 540).
- 'kitti': KITTI's left colour camera (P_rect_02 of the 2011_09_26 drives): 1242 x 375,
  f = 721.5377 (monodepth's width_to_focal[1242], rd-yolo-camera-facts §4), principal point
  (609.5593, 172.854) in KITTI's convention (pixel centres at integers), + 0.5 here.
`scaled(width)` multiplies every intrinsic by width / preset width (the image is resampled, the
field of view is kept); the height is rounded.

Mount (camera_rotation): the camera looks along the ego's heading, pitched down by `pitch`; the
heading is a compass angle, clockwise from north, so forward = (sin h, cos h, 0) in ENU.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class PinholeCamera:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self):
        if self.width < 1 or self.height < 1 or self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"PinholeCamera: {self.width} x {self.height} px with fx={self.fx}, fy={self.fy} > 0")

    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view through the image edges."""
        return math.degrees(math.atan(self.cx / self.fx) + math.atan((self.width - self.cx) / self.fx))

    def scaled(self, width: int) -> "PinholeCamera":
        s = width / self.width
        return PinholeCamera(int(width), max(1, int(round(self.height * s))), self.fx * s, self.fy * s,
                             self.cx * s, self.cy * s)

    def ray_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Per column (W,) and per row (H,): x / z and y / z of the ray through the pixel centre."""
        du = (np.arange(self.width) + 0.5 - self.cx) / self.fx
        dv = (np.arange(self.height) + 0.5 - self.cy) / self.fy
        return du.astype(np.float32), dv.astype(np.float32)

    def project(self, xyz: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame points (z > 0) -> (..., 2) continuous (u, v)."""
        xyz = np.asarray(xyz, np.float64)
        return np.stack([self.cx + self.fx * xyz[..., 0] / xyz[..., 2],
                         self.cy + self.fy * xyz[..., 1] / xyz[..., 2]], -1)

    def describe(self) -> dict:
        return dict(width=self.width, height=self.height, fx=round(self.fx, 4), fy=round(self.fy, 4),
                    cx=round(self.cx, 4), cy=round(self.cy, 4), hfov_deg=round(self.hfov_deg, 2))


PAPER_F = 960.0 / math.tan(math.radians(60.0))
CAMERAS = {
    "paper": PinholeCamera(1920, 1080, PAPER_F, PAPER_F, 960.0, 540.0),
    "kitti": PinholeCamera(1242, 375, 721.5377, 721.5377, 609.5593 + 0.5, 172.854 + 0.5),
}


def heading_vectors(heading: float) -> tuple[np.ndarray, np.ndarray]:
    """(forward, right) unit vectors in ENU of a compass heading (rad, clockwise from north)."""
    s, c = math.sin(heading), math.cos(heading)
    return np.array([s, c, 0.0]), np.array([c, -s, 0.0])


def camera_rotation(heading: float, pitch: float = 0.0) -> np.ndarray:
    """(3, 3) M with rows = the camera's x (right), y (down), z (optical axis) in ENU:
    X_cam = M (X_enu - C), X_enu = C + M.T X_cam."""
    forward, right = heading_vectors(heading)
    up = np.array([0.0, 0.0, 1.0])
    z = math.cos(pitch) * forward - math.sin(pitch) * up
    y = np.cross(z, right)
    return np.stack([right, y, z])

"""Placing a detection in the world: a depth at a reference pixel of its box, the lateral offset,
then East-North-Up and WGS84 (shuffle_yolov3_edge.txt §3.3; reference-spec §2).

Conventions:
- Boxes are (x1, y1, x2, y2) pixel *edges* (boxes/boxes2d.py); pixel (row i, column j) covers
  [j, j + 1) x [i, i + 1), so continuous (u, v) falls in pixel (floor(v), floor(u)).
- Reference points (REFERENCE_POINTS): "center", the box centre, as the paper; "bottom_center",
  the middle of the box's bottom edge, the common alternative (where a road user stands on the
  road, hence the depth of its near ground contact). The read at the bottom centre is moved up
  into the box by BOTTOM_INSET of the box height, and its window is clipped to the box: the bottom
  edge's own pixels are where the road under and beside the object meets its lowest part, the
  boundary a stereo or monocular map smears most, while a tenth of the way up hits the tyres,
  bumper or feet. Measured with the ground-truth depth of the synthetic drives (docs/edge-and-map-service.md):
  the road seen *under* a high-floored truck and through a bicycle's frame still reaches this
  read, so the bottom centre places trucks and cyclists worse than the centre does.
- Either way the depth read is that of the *visible surface*, not of the object's centre: a car
  seen from behind is placed about half its length (2.3 m) short of its centre, a bus 6 m.
- `sample_at` reads a map at reference pixels as the median of the finite values of a small
  window (up to (2 radius + 1)^2 pixels) clipped to the image and to the box. A single pixel is
  one noise draw of a stereo or network map and can fall through the object (a window, a gap
  between a cyclist's wheels, sky between a pedestrian's arms); a median over a few pixels
  inside the box ignores such minority pixels, while a window much larger than the object (a
  median of the whole box) would read the background behind thin objects. The median commutes
  with the monotone disparity-to-depth map (exactly for an odd number of values, the two middle
  values averaged otherwise), so a depth map or a disparity map read here agree.
- Depth (m) is along the optical axis (z), not the ray length; x (m) is lateral, right of the
  optical axis positive: x = (u - cx) depth / fx (reference-spec §2: x = x_c depth / f).
- `place_enu` assumes a level camera looking along the ego's heading psi (compass radians, forward =
  (sin psi, cos psi), right = (cos psi, -sin psi)): E = E0 + depth sin psi + x cos psi,
  N = N0 + depth cos psi - x sin psi, U = U0. U stays the camera's: the paper's map is
  horizontal, depth along a level optical axis is a horizontal distance, and the object's height
  above the road is not estimated (the box's rows would give it only through the camera's pitch,
  which bounces with the car). The plane U = U0 departs from the ego's height by about
  depth x D / 6371 km at D from the frame's origin (3 cm for 40 m at D = 5 km), so alt is the
  camera's GPS height.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .geodesy import enu_to_geodetic

REFERENCE_POINTS = ("center", "bottom_center")
BOTTOM_INSET = 0.1  # of the box height: where "bottom_center" reads, above the bottom edge


def _xyxy(xyxy) -> np.ndarray:
    xyxy = np.asarray(xyxy, np.float64).reshape(-1, 4)
    if not np.all(np.isfinite(xyxy)) or np.any(xyxy[:, 2:] < xyxy[:, :2]):
        raise ValueError("boxes must be finite (x1, y1, x2, y2) with x1 <= x2 and y1 <= y2")
    return xyxy


def reference_pixels(xyxy, mode: str = "center") -> np.ndarray:
    """(N, 4) boxes -> (N, 2) continuous (u, v) where the depth is read (module docstring)."""
    if mode not in REFERENCE_POINTS:
        raise ValueError(f"reference point {mode!r}; expected one of {REFERENCE_POINTS}")
    b = _xyxy(xyxy)
    u = 0.5 * (b[:, 0] + b[:, 2])
    v = 0.5 * (b[:, 1] + b[:, 3]) if mode == "center" else b[:, 3] - BOTTOM_INSET * (b[:, 3] - b[:, 1])
    return np.stack([u, v], -1)


def windows(shape, uv, boxes=None, radius: int = 2) -> list[tuple[slice, slice]]:
    """(rows, columns) slices of the read window around each (u, v): half-size `radius` pixels
    around its pixel, clipped to an image of `shape` (H, W) and, when `boxes` (N, 4) are given, to
    the pixels each box touches."""
    h, w = shape[:2]
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    col = np.clip(np.floor(uv[:, 0]), 0, w - 1).astype(np.int64)
    row = np.clip(np.floor(uv[:, 1]), 0, h - 1).astype(np.int64)
    lo_c, hi_c = np.maximum(col - radius, 0), np.minimum(col + radius, w - 1)
    lo_r, hi_r = np.maximum(row - radius, 0), np.minimum(row + radius, h - 1)
    if boxes is not None:
        b = _xyxy(boxes)
        if len(b) != len(uv):
            raise ValueError(f"{len(b)} boxes for {len(uv)} reference pixels")
        lo_c, hi_c = np.maximum(lo_c, np.floor(b[:, 0])), np.minimum(hi_c, np.ceil(b[:, 2]) - 1)
        lo_r, hi_r = np.maximum(lo_r, np.floor(b[:, 1])), np.minimum(hi_r, np.ceil(b[:, 3]) - 1)
    return [(slice(int(a), int(b) + 1), slice(int(c), int(d) + 1)) for a, b, c, d in zip(lo_r, hi_r, lo_c, hi_c)]


def sample_at(map2d, uv, boxes=None, radius: int = 2) -> np.ndarray:
    """(N,) float64: the median of the finite values of `map2d` (H, W) in each reference pixel's
    window (`windows`). NaN where the window holds no finite value."""
    m = np.asarray(map2d)
    if m.ndim != 2:
        raise ValueError(f"map2d must be (H, W); got shape {m.shape}")
    out = []
    for rows, cols in windows(m.shape, uv, boxes, radius):
        win = m[rows, cols].astype(np.float64)
        win = win[np.isfinite(win)]
        out.append(np.median(win) if win.size else np.nan)
    return np.array(out, np.float64)


def depth_from_disparity(disp, baseline_m: float, focal_px: float, a: float = 1.0) -> np.ndarray:
    """Depth (m) = b f / (a d) for a rectified stereo pair of baseline b (m) and focal length f (px).

    The paper writes depth = a b f / disp with an "adjustment coefficient" a = 1367; read
    literally with f = 1012 and b = 0.54 it gives absurd depths (reference-spec §2 FLAG). The
    consistent reading is b f / (a d) with `a` the factor that turns the disparity into pixels'
    denominators: monodepth's disparity d is a fraction of the image width, so its pixel disparity
    is W d and KITTI's depth = 0.54 f / (W d) (monodepth's evaluation_utils): a = the image width
    converts a monodepth disparity, a = 1 takes a disparity already in pixels (a stereo matcher,
    StreetFrame.disparity()), and any other a is a calibration factor. A disparity of 0 is
    infinitely far (inf); a negative or non-finite one gives NaN."""
    if not (baseline_m > 0 and focal_px > 0 and a > 0):
        raise ValueError(f"baseline_m={baseline_m}, focal_px={focal_px} and a={a} must be > 0")
    d = np.asarray(disp, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = baseline_m * focal_px / (a * d)
    return np.where(np.isfinite(d) & (d >= 0), depth, np.nan)


def lateral_offset(u, depth, cx: float, fx: float) -> np.ndarray:
    """x (m, right of the optical axis positive) = (u - cx) depth / fx."""
    return (np.asarray(u, np.float64) - cx) * np.asarray(depth, np.float64) / fx


def place_enu(depth, x, ego_enu, heading) -> np.ndarray:
    """(..., 3) ENU of objects `depth` ahead and `x` to the right of a level camera at `ego_enu`
    (3,) heading `heading` (compass rad): E0 + depth sin + x cos, N0 + depth cos - x sin, U0."""
    depth, x = np.asarray(depth, np.float64), np.asarray(x, np.float64)
    e0, n0, u0 = np.asarray(ego_enu, np.float64).reshape(3)
    s, c = math.sin(heading), math.cos(heading)
    return np.stack(np.broadcast_arrays(e0 + depth * s + x * c, n0 + depth * c - x * s, u0 + 0 * depth), -1)


@dataclasses.dataclass(frozen=True)
class Placer:
    """Detections + a depth map in metres + the ego's state -> the exchange format's placed-object
    dicts. fx, cx: the camera intrinsics at the depth map's and boxes' resolution; origin: the
    local ENU frame of `ego_enu` (the EgoTrack's origin)."""

    fx: float
    cx: float
    origin: tuple
    reference: str = "center"
    radius: int = 2

    def __post_init__(self):
        if self.reference not in REFERENCE_POINTS:
            raise ValueError(f"reference point {self.reference!r}; expected one of {REFERENCE_POINTS}")
        if not self.fx > 0 or self.radius < 0:
            raise ValueError(f"Placer: fx={self.fx} > 0 and radius={self.radius} >= 0")

    def depths(self, xyxy, depth_map) -> tuple[np.ndarray, np.ndarray]:
        """(N,) depth (m) at each box's reference point and (N,) its u."""
        uv = reference_pixels(xyxy, self.reference)
        return sample_at(depth_map, uv, xyxy, self.radius), uv[:, 0]

    def place(self, xyxy, classes, scores, depth_map, ego_enu, heading_rad: float) -> tuple[list[dict], np.ndarray]:
        """(placed objects, (N,) bool: which detections were placed). A detection whose window holds
        no finite positive depth (sky, an empty map) is not placed: it has no position to give."""
        xyxy = _xyxy(xyxy)
        if not (len(classes) == len(scores) == len(xyxy)):
            raise ValueError(f"{len(xyxy)} boxes, {len(classes)} classes and {len(scores)} scores must match")
        depth, u = self.depths(xyxy, depth_map)
        ok = np.isfinite(depth) & (depth > 0)
        x = lateral_offset(u, depth, self.cx, self.fx)
        enu = place_enu(np.where(ok, depth, 0.0), np.where(ok, x, 0.0), ego_enu, heading_rad)
        lat, lon, alt = enu_to_geodetic(enu, self.origin)
        objects = [{"class": str(classes[k]), "score": float(scores[k]), "box": [float(v) for v in xyxy[k]],
                    "depth_m": float(depth[k]), "x_m": float(x[k]),
                    "lat": float(lat[k]), "lon": float(lon[k]), "alt": float(alt[k])}
                   for k in np.flatnonzero(ok)]
        return objects, ok


def frame_batch(device: str, frame: str, time: float, ego: dict, objects: list[dict], run_id: str | None = None) -> dict:
    """The exchange format's frame batch (what an edge device posts for one frame); batch_id is
    "device:run_id:frame", unique per device, recording run and frame (frame ids restart with each
    recording), or "device:frame" without a run id."""
    batch_id = f"{device}:{run_id}:{frame}" if run_id else f"{device}:{frame}"
    return {"batch_id": batch_id, "device": str(device), "frame": str(frame), "time": float(time),
            "ego": {k: float(ego[k]) for k in ("lat", "lon", "alt", "heading_deg")}, "objects": list(objects)}

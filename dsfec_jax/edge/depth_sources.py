"""Where an edge frame's depth comes from: any source plugs into the same pipeline.

A depth source is a callable `source(frame: EdgeFrame, camera) -> (H, W) float depth map in metres`
along the optical axis (non-finite where there is no depth). The placement reads it at each
detection's reference point (geo.placement).

- `NetworkDepth`: the monodepth network on the left image alone (the paper's §3.2): its disparity d
  is a fraction of the image width, depth = b f / (a d) with a = the image width by default, so
  a d is the disparity in pixels; `a` is the paper's adjustment coefficient, calibrated per camera
  (reference-spec §2 explains the reading).
- `StereoDisparityFiles`: a user's stereo disparity in pixels, one file per frame (depth = b f / d).
- `DepthFiles`: a user's depth map in metres, one file per frame.
- `TruthDepth`: the synthetic drive's exact depth map: the error tables' oracle row, which isolates
  what the reference point, the GPS interpolation and the heading cost.

Files are `<frame_id>.npy` (float, as is) or `<frame_id>.png` (16-bit, KITTI's value / 256 convention;
0 = no value).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geo.placement import depth_from_disparity
from .frames import EdgeFrame

DEPTH_SOURCES = ("network", "truth", "stereo", "depth")
KITTI_PNG_SCALE = 256.0  # KITTI stores disparity and depth as uint16 PNG of value * 256, 0 = none


def read_map(directory: Path, frame_id: str, shape: tuple[int, int], what: str) -> np.ndarray:
    """`directory/<frame_id>.npy` or `.png` -> (H, W) float64, NaN where a PNG holds 0."""
    npy, png = directory / f"{frame_id}.npy", directory / f"{frame_id}.png"
    if npy.is_file():
        values = np.load(npy, allow_pickle=False).astype(np.float64)
    elif png.is_file():
        from PIL import Image

        with Image.open(png) as im:
            raw = np.asarray(im)
        if raw.dtype != np.uint16:
            raise ValueError(f"{png}: {raw.dtype} PNG; a {what} PNG must be 16-bit (value * 256, KITTI)")
        values = np.where(raw > 0, raw / KITTI_PNG_SCALE, np.nan)
    else:
        raise FileNotFoundError(f"{directory}: no {frame_id}.npy or {frame_id}.png ({what} of frame {frame_id})")
    if values.shape != shape:
        raise ValueError(f"{directory}/{frame_id}: {what} map {values.shape}; expected the frame's {shape}")
    return values


class NetworkDepth:
    def __init__(self, predictor, baseline_m: float, a: float | None = None):
        self.predictor, self.baseline_m, self.a = predictor, float(baseline_m), a

    def __call__(self, frame: EdgeFrame, camera) -> np.ndarray:
        disparity = self.predictor(frame.image)  # fraction of the image width
        a = camera.width if self.a is None else self.a
        return depth_from_disparity(disparity, self.baseline_m, camera.fx, a)


class StereoDisparityFiles:
    def __init__(self, directory: str | Path, baseline_m: float):
        self.directory, self.baseline_m = Path(directory), float(baseline_m)

    def __call__(self, frame: EdgeFrame, camera) -> np.ndarray:
        disparity = read_map(self.directory, frame.frame_id, frame.image.shape[:2], "disparity")
        return depth_from_disparity(disparity, self.baseline_m, camera.fx, 1.0)  # already pixels


class DepthFiles:
    def __init__(self, directory: str | Path):
        self.directory = Path(directory)

    def __call__(self, frame: EdgeFrame, camera) -> np.ndarray:
        return read_map(self.directory, frame.frame_id, frame.image.shape[:2], "depth")


class TruthDepth:
    def __call__(self, frame: EdgeFrame, camera) -> np.ndarray:
        if frame.truth is None:
            raise ValueError(f"frame {frame.frame_id}: the 'truth' depth source needs the synthetic drive")
        return np.asarray(frame.truth.depth, np.float64)

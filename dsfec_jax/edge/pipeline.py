"""The edge device's per-frame work (the paper's Fig. 2, edge side): detect, estimate depth, place.

frame -> detector (boxes, classes, scores) -> depth source (a depth map in metres) -> each box's
depth at its reference point and lateral offset (geo.placement) -> the ego's interpolated GPS
position and heading at the frame's time (geo.gps.EgoTrack) -> the objects' ENU and WGS84
positions -> one frame batch (the exchange format the map service stores).

A frame outside the GPS track's coverage (before the first fix, after the last, or inside a gap)
has no ego position: it is skipped and counted, not placed at a guessed position.
Every stage is timed per frame, so `dsfec edge` reports where the frame rate goes.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..boxes.boxes2d import Boxes2D
from ..geo.gps import EgoTrack
from ..geo.placement import Placer, frame_batch
from .frames import EdgeFrame

STAGES = ("detect", "depth", "place")


@dataclasses.dataclass(frozen=True)
class FrameResult:
    batch: dict | None                 # None: the frame was skipped (no GPS coverage)
    detections: Boxes2D | None
    placed: np.ndarray | None          # (N,) bool: detections that got a position
    depth_map: np.ndarray | None
    seconds: dict                      # stage -> wall seconds


class EdgePipeline:
    """`pipeline(frame) -> FrameResult`. detect(image) -> Boxes2D with class names and scores (e.g.
    api.load("shuffle_yolov3")); depth(frame, camera) -> (H, W) metres (edge.depth_sources);
    camera: the frames' PinholeCamera; time_offset_s: added to a frame's time for the batch's UNIX
    time (the synthetic drive's clock starts at 0)."""

    def __init__(self, detect, depth, camera, track: EgoTrack, device: str, reference: str = "center",
                 time_offset_s: float = 0.0):
        self.detect, self.depth, self.camera, self.track = detect, depth, camera, track
        self.device, self.time_offset_s = str(device), float(time_offset_s)
        self.placer = Placer(fx=camera.fx, cx=camera.cx, origin=track.origin, reference=reference)
        self.skipped = 0

    def covered(self, frame: EdgeFrame) -> bool:
        return bool(self.track.covered(frame.time_s))

    def __call__(self, frame: EdgeFrame, run_id: str | None = None) -> FrameResult:
        """run_id: the recording run's id, in the batch id (edge.run keeps it in the run's folder)."""
        if not self.covered(frame):
            self.skipped += 1
            return FrameResult(None, None, None, None, {})
        t0 = time.perf_counter()
        dets = self.detect(frame.image)
        t1 = time.perf_counter()
        depth_map = self.depth(frame, self.camera)
        t2 = time.perf_counter()
        ego = self.track.state(frame.time_s)
        objects, placed = self.placer.place(dets.xyxy, dets.names, dets.scores, depth_map, ego.enu, ego.heading_rad)
        batch = frame_batch(self.device, frame.frame_id, frame.time_s + self.time_offset_s, ego.to_dict(), objects,
                            run_id)
        t3 = time.perf_counter()
        return FrameResult(batch, dets, placed, depth_map, dict(detect=t1 - t0, depth=t2 - t1, place=t3 - t2))

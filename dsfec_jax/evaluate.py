"""Run a predictor over frames and score it with the nuScenes detection AP (DSFEC §4.2)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .data.frame import Frame
from .metrics import kitti3d, nuscenes, resampling
from .predict import Detections, Predictor


def predict_frames(predictor: Predictor, frames: Sequence[Frame], batch_size: int = 8) -> dict[str, Detections]:
    out = {}
    for start in range(0, len(frames), batch_size):
        chunk = [frames[i] for i in range(start, min(start + batch_size, len(frames)))]
        for frame, det in zip(chunk, predictor.predict_batch(chunk)):
            out[frame.frame_id] = det
    return out


def in_grid(boxes, grid):
    """Boxes whose centre lies on the grid: what a detector on that grid can find."""
    return boxes.select(grid.contains(boxes.center[:, 0], boxes.center[:, 1]))


def score(frames: Sequence[Frame], detections: dict[str, Detections], classes=nuscenes.DSFEC_CLASSES,
          grid=None, match_classes: Sequence[str] = ()) -> dict:
    """nuScenes AP per class and threshold, class mAPs, AP@4. Ground-truth boxes are all kept
    (radar-only frames have no lidar count for the devkit's num_pts == 0 filter) except, with
    `grid`, those centred off the detector's grid (DSFEC sees X 0..80 m only, not 360 degrees);
    the devkit's class ranges (car 50 m, pedestrian 40 m, ...) apply, measured from the sensor.
    `match_classes` adds "match_tables": {class: resampling.MatchTable} for bootstrap intervals."""
    frames = [frames[i] for i in range(len(frames))]
    gt = {f.frame_id: (in_grid(f.boxes, grid) if grid is not None else f.boxes) for f in frames}
    pred = {token: (d.boxes, d.scores) for token, d in detections.items()}
    out = nuscenes.evaluate(gt, pred, classes=classes, drop_empty_gt=False)
    if match_classes:
        out["match_tables"] = {c: resampling.match_table(gt, pred, c, drop_empty_gt=False) for c in match_classes}
    return out


def headline(metrics: dict) -> dict:
    """The paper's figures: Car mAP over 0.5/1/2/4 m and Car AP@4, plus the all-class mAP (in %)."""
    car = "car" in metrics["class_mAP"]
    return {"car_mAP": 100 * metrics["class_mAP"]["car"] if car else None,
            "car_AP4": 100 * metrics["AP@4"]["car"] if car else None,
            "mAP": 100 * metrics["mAP"]}


def evaluate(predictor: Predictor, frames: Sequence[Frame], classes=nuscenes.DSFEC_CLASSES,
             match_classes: Sequence[str] = ()) -> dict:
    metrics = score(frames, predict_frames(predictor, frames), classes, predictor.spec.grid, match_classes)
    return {**headline(metrics), "metrics": metrics}


# VoD's IoU thresholds under the project's canonical class names (VoD's Cyclist is "bicycle").
VOD_IOU = {"car": 0.5, "pedestrian": 0.25, "bicycle": 0.25}
TJ4D_IOU = {**VOD_IOU, "truck": 0.5}


def _kitti_frame(boxes, scores=None) -> dict:
    out = {"names": list(boxes.names), "boxes": np.column_stack([boxes.center, boxes.size, boxes.yaw]).reshape(-1, 7)}
    if scores is not None:
        out["scores"] = np.asarray(scores)
    return out


def evaluate_vod(predictor, frames: Sequence[Frame], iou_thresholds: dict | None = None) -> dict:
    """Predict `frames`, then `score_vod` them with the predictor's classes and grid."""
    frames = [frames[i] for i in range(len(frames))]
    return score_vod(frames, predict_frames(predictor, frames), predictor.spec.grid, predictor.class_names,
                     iou_thresholds)


def score_vod(frames: Sequence[Frame], detections: dict, grid, class_names, iou_thresholds: dict | None = None) -> dict:
    """The View-of-Delft protocol (3D AP, 11 recall points) in the entire area and the corridor:
    headline mAP (entire), mAP_corridor, per-class AP of both. Ground truth centred off the
    detector's grid is left out, as in `score`. The IoU thresholds default to VoD's / TJ4D's
    for `class_names` (Car and Truck 0.5, Pedestrian and Cyclist 0.25); a class with no ground
    truth has AP NaN and stays out of the mAP."""
    if iou_thresholds is None:
        iou_thresholds = {c: TJ4D_IOU[c] for c in class_names}
    frames = [frames[i] for i in range(len(frames))]
    gts = [_kitti_frame(in_grid(f.boxes, grid)) for f in frames]
    dets = [_kitti_frame(detections[f.frame_id].boxes, detections[f.frame_id].scores) for f in frames]
    both = kitti3d.evaluate_vod(gts, dets, iou_thresholds)
    entire, corridor = both["entire"], both["corridor"]
    return {"mAP": entire["mAP"], "mAP_corridor": corridor["mAP"], "AP": entire["AP"],
            "AP_corridor": corridor["AP"], "num_gt": entire["num_gt"]}

"""Run a predictor over frames and score it with the nuScenes detection AP (DSFEC §4.2)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ...data.points.frame import Frame
from ...data.points.kitti import VOD_IMAGE_SIZE, VOD_RADAR_TO_CAMERA
from ...metrics import kitti3d, nuscenes, resampling
from ..base import Protocol
from .predict import Detections, HostPipeline


def in_grid(boxes, grid):
    """Boxes whose centre lies on the grid: what a detector on that grid can find."""
    return boxes.select(grid.contains(boxes.center[:, 0], boxes.center[:, 1]))


def score(frames: Sequence[Frame], detections: dict[str, Detections], classes=nuscenes.DSFEC_CLASSES,
          grid=None, match_classes: Sequence[str] = ()) -> dict:
    """nuScenes AP per class and threshold, class mAPs, AP@4, with the devkit's ground-truth filters:
    the class ranges (car 50 m, pedestrian 40 m, ...) measured from the sensor, and num_pts == 0.

    num_pts: a box that carries counts (`Boxes.num_pts`: nuScenes frames, num_lidar_pts +
    num_radar_pts) is dropped at 0, as the devkit does: nothing saw it, so it is not a miss.
    Frames without counts (synthetic ones: no lidar is simulated) keep every box, scored as if a
    lidar had seen every annotated object. Counting radar points instead is not the devkit's rule
    (its num_pts adds the lidar points, which reach most objects the radar misses) and would drop
    exactly the objects the radar missed, flattering a radar detector; keeping them is the stricter
    choice, and it leaves the synthetic figures as they were.
    With `grid`, ground truth centred off the detector's grid is left out too (DSFEC sees X 0..80 m
    only, not 360 degrees). `match_classes` adds "match_tables": {class: resampling.MatchTable}
    for bootstrap intervals. Zero frames raise ValueError."""
    frames = [frames[i] for i in range(len(frames))]
    if not frames:
        raise ValueError("no frames to score: the frame sequence is empty (an empty split?)")
    gt = {f.frame_id: (in_grid(f.boxes, grid) if grid is not None else f.boxes) for f in frames}
    pred = {token: (d.boxes, d.scores) for token, d in detections.items()}
    out = nuscenes.evaluate(gt, pred, classes=classes)
    if match_classes:
        out["match_tables"] = {c: resampling.match_table(gt, pred, c) for c in match_classes}
    return out


def headline(metrics: dict) -> dict:
    """The paper's figures: Car mAP over 0.5/1/2/4 m and Car AP@4, plus the all-class mAP (in %)."""
    car = "car" in metrics["class_mAP"]
    return {"car_mAP": 100 * metrics["class_mAP"]["car"] if car else None,
            "car_AP4": 100 * metrics["AP@4"]["car"] if car else None,
            "mAP": 100 * metrics["mAP"]}


def evaluate(predictor: HostPipeline, frames: Sequence[Frame], classes=nuscenes.DSFEC_CLASSES,
             match_classes: Sequence[str] = ()) -> dict:
    metrics = score(frames, predictor.predict_samples(frames), classes, predictor.spec.grid, match_classes)
    return {**headline(metrics), "metrics": metrics}


# VoD's IoU thresholds under the project's canonical class names (VoD's Cyclist is "bicycle").
VOD_IOU = {"car": 0.5, "pedestrian": 0.25, "bicycle": 0.25}
TJ4D_IOU = {**VOD_IOU, "truck": 0.5}


# VoD's 40 px image-height rule applies to VoD frames only: TJ4DRadSet's own evaluation
# (TJRadarLab/TJ4DRadSet docs/eval.py) has the height cut switched off, and synthetic frames have no camera.
HEIGHT_RULE_SOURCES = ("vod",)


def _kitti_frame(boxes, scores=None, **camera) -> dict:
    """kitti3d's frame dict: sensor-frame boxes, plus the camera entries (cam_from_sensor, P2, ...)."""
    out = {"names": list(boxes.names), "boxes": np.column_stack([boxes.center, boxes.size, boxes.yaw]).reshape(-1, 7),
           **camera}
    if scores is not None:
        out["scores"] = np.asarray(scores)
    return out


def _camera(frame: Frame) -> dict:
    """The camera facts VoD's protocol needs: cam_from_sensor for the corridor (the frame's calibration;
    frames without one, i.e. the VoD-like synthetic 4D benchmark, get VoD's nominal radar -> camera
    transform, data.points.kitti.VOD_RADAR_TO_CAMERA), and for VoD frames P2 and the image size, with which
    detections' 3D boxes are projected for the 40 px rule."""
    calib = frame.meta.get("calib")
    if calib is None:
        return {"cam_from_sensor": np.vstack([VOD_RADAR_TO_CAMERA, [0.0, 0.0, 0.0, 1.0]])}
    camera = {"cam_from_sensor": calib.cam_from_sensor()}
    if frame.source in HEIGHT_RULE_SOURCES:
        camera.update(P2=calib.P2, image_size=frame.meta.get("image_size", VOD_IMAGE_SIZE))
    return camera


def _label_heights(frame: Frame) -> np.ndarray:
    """(M,) pixel heights of the frame's label 2D boxes (VoD's ground truth 40 px rule reads these)."""
    labels = frame.meta["kitti_labels"]
    if len(labels) != len(frame.boxes):
        raise ValueError(f"frame {frame.frame_id!r}: meta['kitti_labels'] has {len(labels)} rows for "
                         f"{len(frame.boxes)} boxes; expected them aligned (select both, as "
                         f"data.points.sources.canonical_classes does)")
    return labels.bbox[:, 3] - labels.bbox[:, 1]


def evaluate_vod(predictor, frames: Sequence[Frame], iou_thresholds: dict | None = None) -> dict:
    """Predict `frames`, then `score_vod` them with the predictor's classes and grid."""
    frames = [frames[i] for i in range(len(frames))]
    return score_vod(frames, predictor.predict_samples(frames), predictor.spec.grid, predictor.class_names,
                     iou_thresholds)


def score_vod(frames: Sequence[Frame], detections: dict, grid, class_names, iou_thresholds: dict | None = None) -> dict:
    """The View-of-Delft protocol (3D AP, 11 recall points) in the entire area and the corridor
    (camera |x| <= 4 m, z <= 25 m, through each frame's calibration, see `_camera`): headline mAP
    (entire), mAP_corridor, per-class AP and ground-truth counts of both. VoD frames also apply
    the 40 px rule: ground truth by its label's 2D box, detections by their projected 3D box.
    Ground truth centred off the detector's grid is left out, as in `score`. The IoU thresholds
    default to VoD's / TJ4D's for `class_names` (Car and Truck 0.5, Pedestrian and Cyclist 0.25);
    a class with no ground truth has AP NaN and stays out of the mAP. Zero frames raise ValueError."""
    if iou_thresholds is None:
        iou_thresholds = {c: TJ4D_IOU[c] for c in class_names}
    frames = [frames[i] for i in range(len(frames))]
    if not frames:
        raise ValueError("no frames to score: the frame sequence is empty (an empty split?)")
    gts, dets = [], []
    for f in frames:
        camera = _camera(f)
        on_grid = grid.contains(f.boxes.center[:, 0], f.boxes.center[:, 1])
        label = {"bbox_height": _label_heights(f)[on_grid]} if "P2" in camera and "kitti_labels" in f.meta else {}
        gts.append(_kitti_frame(f.boxes.select(on_grid), **camera, **label))
        dets.append(_kitti_frame(detections[f.frame_id].boxes, detections[f.frame_id].scores, **camera))
    both = kitti3d.evaluate_vod(gts, dets, iou_thresholds)
    entire, corridor = both["entire"], both["corridor"]
    return {"mAP": entire["mAP"], "mAP_corridor": corridor["mAP"], "AP": entire["AP"],
            "AP_corridor": corridor["AP"], "num_gt": entire["num_gt"], "num_gt_corridor": corridor["num_gt"]}


# --- the point protocols (the record's `protocols`: modalities/points/record.py)

def validate_nuscenes(predictor, frames, match_classes: Sequence[str] = ()) -> tuple[dict, dict]:
    result = evaluate(predictor, frames, match_classes=match_classes)
    m = result.pop("metrics")
    return {**result, "class_mAP": m["class_mAP"], "AP@4": m.get("AP@4", {})}, m.get("match_tables", {})


def validate_vod(predictor, frames, match_classes: Sequence[str] = ()) -> tuple[dict, dict]:
    return evaluate_vod(predictor, frames), {}


def report_nuscenes(frames, detections, predictor) -> tuple[dict, str]:
    metrics = score(frames, detections, grid=predictor.spec.grid)
    result = {"protocol": "nuscenes", **headline(metrics), "metrics": metrics}
    return result, (f"Car mAP {result['car_mAP']:.2f}  Car AP@4 {result['car_AP4']:.2f}  "
                    f"mAP(all classes) {result['mAP']:.2f}")


def report_vod(frames, detections, predictor) -> tuple[dict, str]:
    result = {"protocol": "vod", **score_vod(frames, detections, predictor.spec.grid, predictor.class_names)}
    return result, f"VoD 3D mAP {result['mAP']:.2f}  corridor {result['mAP_corridor']:.2f}  " + "  ".join(
        f"{c} {ap:.2f}" for c, ap in result["AP"].items())


# the protocols a point family's MetricProtocol may name (the record's `protocols`)
PROTOCOLS = {"nuscenes": Protocol(validate_nuscenes, report_nuscenes), "vod": Protocol(validate_vod, report_vod)}

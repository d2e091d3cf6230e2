"""The View-of-Delft 3D AP (official VoD / KITTI evaluation, as RadarNeXt reports it).

- 3D IoU of oriented boxes: rotated BEV overlap x height overlap over the union of volumes.
- Per class, one IoU threshold (VoD: Car 0.5, Pedestrian 0.25, Cyclist 0.25; TJ4D adds Truck 0.5).
- KITTI matching: every ground truth takes the unassigned detection with the highest score
  (collecting the scores of true positives) or, when counting false positives at a score
  threshold, the highest overlap. 41 score thresholds are sampled from the true-positive scores
  at recall steps of 1/40; precision is made monotone (max over higher recalls) and AP averages
  the precisions at sample points 0, 4, ..., 40 (11 recall points), in percent.
- Ignored boxes are neither missed nor false positives when matched (VoD's clean_data):
  ground truth of a neighbouring class (a Van for Car, a Person_sitting for Pedestrian), or of
  the class but outside the region or at most 40 px tall in the image; detections of ANY class
  that are outside the region or under 40 px tall. Any other class is not scored at all.
- Regions: the entire annotated area, or the driving corridor (VoD's roi): camera-frame
  |x| <= 4 m and z <= 25 m, tested on the box's bottom centre (KITTI's label location). Boxes
  are in the sensor (radar) frame, so the corridor needs each frame's `cam_from_sensor`.
- The 40 px rule needs a camera: a frame's `bbox_height` (pixels, e.g. the labels' 2D boxes)
  or, without it, `P2` and `image_size`, with which the 3D boxes are projected and the image
  box clipped to the image, as a detector's KITTI writer does for its detections.

Frames are dicts: names (N,), boxes (N, 7) as (x, y, z centre, w, l, h, yaw) in the sensor frame,
detections also scores (N,); optional: cam_from_sensor (4, 4) sensor -> rectified camera,
bbox_height (N,), P2 (3, 4) and image_size (width, height). Facts from the VoD devkit
(github tudelft-iv/view-of-delft-dataset, vod/evaluation/kitti_official_evaluate.py and
evaluate.py); the code is ours.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from dsfec_jax.boxes.geometry import bev_corners
from dsfec_jax.boxes.rotated_iou import iou_3d

N_SAMPLE_PTS = 41
VOD_IOU = {"Car": 0.5, "Pedestrian": 0.25, "Cyclist": 0.25}
TJ4D_IOU = {"Car": 0.5, "Pedestrian": 0.25, "Cyclist": 0.25, "Truck": 0.5}
NEIGHBOURS = {"car": ("van",), "pedestrian": ("person_sitting",)}
MIN_HEIGHT_PX = 40.0
CORRIDOR = {"max_abs_x": 4.0, "max_z": 25.0}  # camera frame (x right, z forward), metres
REGIONS = ("entire", "corridor")
VALID, IGNORED, OTHER = 0, 1, -1
NO_DETECTION = -1e7


def _frame_arrays(frame: Mapping, is_det: bool, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    names = np.array([str(n).lower() for n in frame.get("names", [])], dtype=object)
    boxes = np.asarray(frame.get("boxes", np.zeros((0, 7))), np.float64).reshape(-1, 7) if len(names) else np.zeros((0, 7))
    if len(boxes) != len(names):
        raise ValueError(f"{where}: {len(names)} names but {len(boxes)} boxes; expected one (x,y,z,w,l,h,yaw) row per name")
    scores = np.zeros(len(names))
    if is_det:
        if "scores" not in frame:
            raise ValueError(f"{where}: detections need 'scores' (one per box)")
        scores = np.asarray(frame["scores"], np.float64).reshape(-1)
        if len(scores) != len(names):
            raise ValueError(f"{where}: {len(scores)} scores for {len(names)} boxes")
    return names, boxes, scores


def camera_locations(boxes: np.ndarray, cam_from_sensor: np.ndarray) -> np.ndarray:
    """(N, 3) bottom centres in the camera frame: KITTI's label `location`, where VoD tests its corridor.
    Boxes are upright in the (z-up) sensor frame, so the bottom centre is z - h/2 there."""
    bottom = boxes[:, :3].copy()
    bottom[:, 2] -= boxes[:, 5] / 2
    return bottom @ cam_from_sensor[:3, :3].T + cam_from_sensor[:3, 3]


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """(N, 8, 3) corners of (x, y, z centre, w, l, h, yaw) boxes: the BEV corners at bottom and top."""
    bev = bev_corners(boxes[:, :2], boxes[:, 3:5], boxes[:, 6])
    z = boxes[:, 2:3] + np.array([-0.5, 0.5]) * boxes[:, 5:6]  # (N, 2) bottom, top
    return np.concatenate([np.dstack([bev, np.repeat(z[:, i : i + 1], 4, 1)]) for i in range(2)], 1)


def projected_heights(boxes: np.ndarray, cam_from_sensor: np.ndarray, P2: np.ndarray, image_size) -> np.ndarray:
    """(N,) pixel heights of the boxes' image boxes: the 8 corners projected with P2, the box clipped
    to the image (0..height), as KITTI writers make a 3D detection's 2D box. Depths are floored at
    0.1 m: a corner at or behind the camera plane has no meaningful projection."""
    cam = box_corners(boxes) @ cam_from_sensor[:3, :3].T + cam_from_sensor[:3, 3]
    uvw = cam @ P2[:, :3].T + P2[:, 3]
    v = uvw[..., 1] / np.maximum(uvw[..., 2], 0.1)
    height = float(image_size[1])
    return np.clip(v.max(1), 0, height) - np.clip(v.min(1), 0, height)


def _matrix(frame: Mapping, key: str, shape: tuple, where: str) -> np.ndarray:
    value = np.asarray(frame[key], np.float64)
    if value.shape != shape or not np.all(np.isfinite(value)):
        raise ValueError(f"{where}: {key!r} has shape {value.shape}; expected finite {shape}")
    return value


def _ignore_masks(boxes: np.ndarray, frame: Mapping, region: str, detection: bool,
                  where: str) -> tuple[np.ndarray, np.ndarray]:
    """(outside the region, too small in the image): the two reasons the protocol ignores a box."""
    outside = np.zeros(len(boxes), bool)
    if region == "corridor":
        if "cam_from_sensor" not in frame:
            raise ValueError(f"{where}: the corridor is defined in the camera frame; the frame needs "
                             f"'cam_from_sensor' (4x4 sensor -> camera)")
        loc = camera_locations(boxes, _matrix(frame, "cam_from_sensor", (4, 4), where))
        outside = (np.abs(loc[:, 0]) > CORRIDOR["max_abs_x"]) | (loc[:, 2] > CORRIDOR["max_z"])
    h = _heights(boxes, frame, where)
    small = np.zeros(len(boxes), bool) if h is None else (h < MIN_HEIGHT_PX) if detection else (h <= MIN_HEIGHT_PX)
    return outside, small


def _heights(boxes: np.ndarray, frame: Mapping, where: str) -> np.ndarray | None:
    """Image heights (pixels): given (`bbox_height`), projected (`P2`, `image_size`), or None (no camera)."""
    if "bbox_height" in frame:
        h = np.asarray(frame["bbox_height"], np.float64).reshape(-1)
        if len(h) != len(boxes):
            raise ValueError(f"{where}: {len(h)} bbox_height values for {len(boxes)} boxes")
        return h
    if "P2" not in frame:
        return None
    if "cam_from_sensor" not in frame or "image_size" not in frame:
        raise ValueError(f"{where}: projecting boxes with 'P2' also needs 'cam_from_sensor' and 'image_size'")
    size = np.asarray(frame["image_size"], np.float64).reshape(-1)
    if size.shape != (2,) or not np.all(size > 0):
        raise ValueError(f"{where}: image_size={frame['image_size']!r}; expected (width, height) > 0")
    return projected_heights(boxes, _matrix(frame, "cam_from_sensor", (4, 4), where),
                             _matrix(frame, "P2", (3, 4), where), size)


def gt_flags(names, outside, small, cls: str) -> np.ndarray:
    """VALID: counts toward recall; IGNORED: may absorb a detection; OTHER: not this class."""
    cls = cls.lower()
    same, neighbour = names == cls, np.isin(names, NEIGHBOURS.get(cls, ()))
    flags = np.full(len(names), OTHER)
    flags[neighbour | (same & (outside | small))] = IGNORED
    flags[same & ~outside & ~small] = VALID
    return flags


def det_flags(names, outside, small, cls: str) -> np.ndarray:
    """As VoD's clean_data: a detection outside the region or too small in the image is IGNORED
    whatever its class (it may absorb a ground truth's match, never a false positive)."""
    flags = np.where(names == cls.lower(), VALID, OTHER)
    flags[outside | small] = IGNORED
    return flags


def match_frame(overlaps, gt_flag, det_flag, scores, min_overlap: float, thresh: float = 0.0,
                compute_fp: bool = False) -> tuple[int, int, int, list]:
    """KITTI's per-frame statistics: (tp, fp, fn, scores of the true positives).
    overlaps is (detections, ground truths)."""
    assigned = np.zeros(len(scores), bool)
    usable = det_flag != OTHER
    if compute_fp:
        usable &= scores >= thresh
    tp = fn = 0
    tp_scores = []
    for i in np.flatnonzero(gt_flag != OTHER):
        candidates = usable & ~assigned & (overlaps[:, i] > min_overlap)
        j = _pick(candidates, overlaps[:, i], det_flag, scores, compute_fp)
        if j < 0:
            fn += gt_flag[i] == VALID
        elif gt_flag[i] == IGNORED or det_flag[j] == IGNORED:
            assigned[j] = True
        else:
            tp += 1
            tp_scores.append(scores[j])
            assigned[j] = True
    fp = int((usable & ~assigned & (det_flag == VALID)).sum()) if compute_fp else 0
    return tp, fp, int(fn), tp_scores


def _pick(candidates, overlap_col, det_flag, scores, compute_fp: bool) -> int:
    """The detection a ground truth takes: best score (thresholds pass), else the best-overlap
    valid detection, falling back to an ignored one only when no valid one overlaps."""
    idx = np.flatnonzero(candidates)
    if not len(idx):
        return -1
    if not compute_fp:
        return int(idx[np.argmax(scores[idx])])
    valid = idx[det_flag[idx] == VALID]
    if len(valid):
        return int(valid[np.argmax(overlap_col[valid])])
    return int(idx[0])


def score_thresholds(tp_scores: Sequence[float], num_gt: int, num_points: int = N_SAMPLE_PTS) -> np.ndarray:
    """KITTI's get_thresholds: one score per 1/(num_points - 1) step of recall."""
    scores = np.sort(np.asarray(tp_scores, np.float64))[::-1]
    thresholds, current = [], 0.0
    for i, score in enumerate(scores):
        left = (i + 1) / num_gt
        right = (i + 2) / num_gt if i < len(scores) - 1 else left
        if right - current < current - left and i < len(scores) - 1:
            continue
        thresholds.append(score)
        current += 1.0 / (num_points - 1)
    return np.array(thresholds)


def average_precision_11(precision: np.ndarray) -> float:
    """Monotone precision over the 41 sample points; mean of points 0, 4, ..., 40, in percent."""
    p = np.zeros(N_SAMPLE_PTS)
    p[: len(precision)] = precision
    p = np.maximum.accumulate(p[::-1])[::-1]
    return float(p[::4].sum() / 11 * 100)


def class_ap(frames: list, cls: str, min_overlap: float) -> dict:
    """AP of one class over prepared frames: list of (overlaps, gt_flag, det_flag, scores)."""
    num_gt, tp_scores = 0, []
    for overlaps, gt_flag, det_flag, scores in frames:
        num_gt += int((gt_flag == VALID).sum())
        tp_scores += match_frame(overlaps, gt_flag, det_flag, scores, min_overlap)[3]
    if num_gt == 0:
        return {"ap": float("nan"), "num_gt": 0, "precision": [], "recall": []}
    thresholds = score_thresholds(tp_scores, num_gt)
    stats = np.zeros((len(thresholds), 3))
    for k, t in enumerate(thresholds):
        for overlaps, gt_flag, det_flag, scores in frames:
            stats[k] += match_frame(overlaps, gt_flag, det_flag, scores, min_overlap, t, True)[:3]
    tp, fp, fn = stats.T
    precision = tp / np.maximum(tp + fp, 1)
    recall = tp / np.maximum(tp + fn, 1)
    return {"ap": average_precision_11(precision), "num_gt": num_gt,
            "precision": precision.round(6).tolist(), "recall": recall.round(6).tolist()}


def evaluate(gts: Sequence[Mapping], dets: Sequence[Mapping], iou_thresholds: Mapping[str, float] = VOD_IOU,
             region: str = "entire") -> dict:
    """3D AP per class and their mean (classes without ground truth are left out of the mean)."""
    if region not in REGIONS:
        raise ValueError(f"region={region!r}; expected one of {REGIONS}")
    if len(gts) != len(dets):
        raise ValueError(f"{len(gts)} ground-truth frames but {len(dets)} detection frames; expected one each")
    if not len(gts):
        raise ValueError("no frames to score: an AP over zero frames is undefined")
    prepared = []
    for f, (gt, det) in enumerate(zip(gts, dets)):
        g_names, g_boxes, _ = _frame_arrays(gt, False, f"ground truth frame {f}")
        d_names, d_boxes, d_scores = _frame_arrays(det, True, f"detections frame {f}")
        overlaps = iou_3d(d_boxes, g_boxes) if len(d_boxes) and len(g_boxes) else np.zeros((len(d_boxes), len(g_boxes)))
        prepared.append((g_names, _ignore_masks(g_boxes, gt, region, False, f"ground truth frame {f}"), d_names,
                         _ignore_masks(d_boxes, det, region, True, f"detections frame {f}"), d_scores, overlaps))
    per_class = {}
    for cls, thr in iou_thresholds.items():
        frames = [(ov, gt_flags(gn, *gm, cls), det_flags(dn, *dm, cls), ds) for gn, gm, dn, dm, ds, ov in prepared]
        per_class[cls] = class_ap(frames, cls, thr)
    aps = [r["ap"] for r in per_class.values() if r["num_gt"]]
    return {"region": region, "AP": {c: r["ap"] for c, r in per_class.items()},
            "mAP": float(np.mean(aps)) if aps else float("nan"),
            "num_gt": {c: r["num_gt"] for c, r in per_class.items()},
            "iou_thresholds": dict(iou_thresholds), "curves": per_class}


def evaluate_vod(gts, dets, iou_thresholds: Mapping[str, float] = VOD_IOU) -> dict:
    """Both of VoD's regions: {'entire': ..., 'corridor': ...}."""
    return {region: evaluate(gts, dets, iou_thresholds, region) for region in REGIONS}

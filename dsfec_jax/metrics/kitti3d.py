"""The View-of-Delft 3D AP (official VoD / KITTI evaluation, as RadarNeXt reports it).

- 3D IoU of oriented boxes: rotated BEV overlap x height overlap over the union of volumes.
- Per class, one IoU threshold (VoD: Car 0.5, Pedestrian 0.25, Cyclist 0.25; TJ4D adds Truck 0.5).
- KITTI matching: every ground truth takes the unassigned detection with the highest score
  (collecting the scores of true positives) or, when counting false positives at a score
  threshold, the highest overlap. 41 score thresholds are sampled from the true-positive scores
  at recall steps of 1/40; precision is made monotone (max over higher recalls) and AP averages
  the precisions at sample points 0, 4, ..., 40 (11 recall points), in percent.
- Neighbouring classes (a Van for Car, a Person_sitting for Pedestrian) and boxes outside the
  evaluated region are *ignored*: they are neither missed nor false positives when matched.
- Regions: the entire annotated area, or the driving corridor (VoD's roi: camera |x| <= 4 m and
  z <= 25 m), applied here in the radar frame as |y| <= 4 m and x <= 25 m, i.e. ignoring the
  sensors' ~0.1 m lateral offset.
- VoD also ignores boxes whose 2D image box is at most 40 px tall; that needs a camera, so it is
  applied only when frames carry `bbox_height` (pixels) for their boxes.

Frames are dicts: names (N,), boxes (N, 7) as (x, y, z centre, w, l, h, yaw), detections also
scores (N,). Facts from ../shared/docs/reference-spec.md §1; the code is ours.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from dsfec_jax.boxes.rotated_iou import iou_3d

N_SAMPLE_PTS = 41
VOD_IOU = {"Car": 0.5, "Pedestrian": 0.25, "Cyclist": 0.25}
TJ4D_IOU = {"Car": 0.5, "Pedestrian": 0.25, "Cyclist": 0.25, "Truck": 0.5}
NEIGHBOURS = {"car": ("van",), "pedestrian": ("person_sitting",)}
MIN_HEIGHT_PX = 40.0
CORRIDOR = {"max_abs_y": 4.0, "max_x": 25.0}
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


def _ignore_masks(boxes: np.ndarray, frame: Mapping, region: str, detection: bool) -> tuple[np.ndarray, np.ndarray]:
    """(outside the region, too small in the image): the two reasons the protocol ignores a box.
    Image heights are known only when the frame carries `bbox_height` (pixels)."""
    outside = np.zeros(len(boxes), bool)
    if region == "corridor":
        outside = (np.abs(boxes[:, 1]) > CORRIDOR["max_abs_y"]) | (boxes[:, 0] > CORRIDOR["max_x"])
    small = np.zeros(len(boxes), bool)
    if "bbox_height" in frame:
        h = np.asarray(frame["bbox_height"], np.float64).reshape(-1)
        small = (h < MIN_HEIGHT_PX) if detection else (h <= MIN_HEIGHT_PX)
    return outside, small


def gt_flags(names, outside, small, cls: str) -> np.ndarray:
    """VALID: counts toward recall; IGNORED: may absorb a detection; OTHER: not this class."""
    cls = cls.lower()
    same, neighbour = names == cls, np.isin(names, NEIGHBOURS.get(cls, ()))
    flags = np.full(len(names), OTHER)
    flags[neighbour | (same & (outside | small))] = IGNORED
    flags[same & ~outside & ~small] = VALID
    return flags


def det_flags(names, outside, small, cls: str) -> np.ndarray:
    """As KITTI's clean_data: a detection too small in the image is IGNORED whatever its class."""
    same = names == cls.lower()
    flags = np.full(len(names), OTHER)
    flags[same & ~outside] = VALID
    flags[(same & outside) | small] = IGNORED
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
    prepared = []
    for f, (gt, det) in enumerate(zip(gts, dets)):
        g_names, g_boxes, _ = _frame_arrays(gt, False, f"ground truth frame {f}")
        d_names, d_boxes, d_scores = _frame_arrays(det, True, f"detections frame {f}")
        overlaps = iou_3d(d_boxes, g_boxes) if len(d_boxes) and len(g_boxes) else np.zeros((len(d_boxes), len(g_boxes)))
        prepared.append((g_names, _ignore_masks(g_boxes, gt, region, False), d_names,
                         _ignore_masks(d_boxes, det, region, True), d_scores, overlaps))
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

"""PASCAL VOC AP (VOC07 11-point and all-point), computed as py-faster-rcnn's voc_eval.py does, so
that a number here can be put beside the VOC mAP@0.5 of the detection papers.

Facts from rbgirshick/py-faster-rcnn `lib/datasets/voc_eval.py` (voc_eval, voc_ap); the code is ours:

- Per class, the class's detections of all images sorted by descending confidence. Each one is
  compared with the ground truths of its image and class; only the one with the highest IoU (the
  first in file order at a tie), difficult or not, is considered.
- It is a match when that IoU > the threshold (strict). A match to a difficult ground truth is
  neither TP nor FP; a match to a ground truth already taken, and no match, are FP.
- npos = the class's non-difficult ground truths; recall = cumTP / npos, precision =
  cumTP / max(cumTP + cumFP, eps).
- VOC07 (`use_07_metric`): the mean over t in np.arange(0., 1.1, 0.1) of the max precision at
  recall >= t (0 where no recall reaches t). Those t are voc_eval's floats: the fourth one is
  0.30000000000000004, so a recall of exactly 3/10 does not reach it; we keep them.
- All-point: sentinels (0, 0) and (1, 0), the monotone precision envelope, the area under it at
  the recall steps.
- IoU with "+1" widths, (x2 - x1 + 1) * (y2 - y1 + 1), on VOC's 1-based inclusive coordinates.

Conventions, as parameters, so that other codes' numbers can be reproduced:
- `convention="edges"` (default): boxes are Boxes2D pixel edges, and IoU has no +1. The VOC reader
  (data/camera/voc.py) maps VOC's inclusive (xmin, ymin, xmax, ymax) to edges (xmin - 1, ymin - 1,
  xmax, ymax), whose width is voc_eval's xmax - xmin + 1, so this default IS voc_eval's "+1" IoU on
  the file's numbers (bit for bit on integer coordinates). `convention="inclusive"`: the boxes hold
  numbers that voc_eval's formula is applied to as they are, +1 added to every width, height and
  intersection side: raw VOC numbers (voc_eval verbatim), or the (x, y, x + w, y + h) that
  rafaelpadilla/review_object_detection_metrics feeds the same formula (its toy oracle needs it).
- `strict=True`: IoU > threshold (voc_eval); False: IoU >= threshold (Padilla, COCO).

Classes: ap is NaN for a class with no non-difficult ground truth (npos = 0), and mAP is the mean
over the classes with npos > 0 (NaN if none). voc_eval divides by npos = 0 there (a RuntimeWarning)
and returns 0 (VOC07) or NaN (all-point) when the class has detections; py-faster-rcnn averages all
20 classes, which is the same on VOC's test sets, where every class has ground truth. A class with
ground truth but no detection scores 0 (voc_ap's value for an empty curve; py-faster-rcnn's own
voc_eval raises IndexError on an empty detection list, later copies guard it and get 0).

Where we differ, only at exact ties: confidence ties keep input order (sample order of `gts`, then
the order within a sample: a stable sort); voc_eval uses np.argsort's default quicksort, whose tie
order is not specified beyond 16 detections. Boxes2D holds float32, so coordinates are exact for
integers below 2**24 and scores differ from float64 files only past their 7th digit.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from ...boxes.boxes2d import Boxes2D
from .frames import checked_boxes, checked_scores, class_table, label_indices, paired_frames, score_order

VOC_METRICS = ("voc07", "all")
CONVENTIONS = ("edges", "inclusive")
VOC07_RECALL_POINTS = np.arange(0.0, 1.1, 0.1)  # voc_eval's own 11 floats, 0.30000000000000004 included


@dataclasses.dataclass(frozen=True)
class VocAP:
    classes: tuple[str, ...]
    ap: np.ndarray         # (C,) float64; NaN for a class with npos == 0
    npos: np.ndarray       # (C,) int64 non-difficult ground truths
    n_det: np.ndarray      # (C,) int64 detections
    metric: str            # "voc07" or "all"
    iou_threshold: float

    @property
    def scored(self) -> np.ndarray:
        return self.npos > 0

    @property
    def map(self) -> float:
        """Mean AP over the classes with npos > 0; NaN when no class has one."""
        return float(np.mean(self.ap[self.scored])) if self.scored.any() else math.nan

    def as_dict(self) -> dict:
        """JSON-ready (NaN -> None)."""
        def num(x: float):
            return None if math.isnan(x) else float(x)
        return {"metric": self.metric, "iou_threshold": self.iou_threshold, "mAP": num(self.map),
                "classes": {name: {"ap": num(self.ap[c]), "npos": int(self.npos[c]), "n_det": int(self.n_det[c])}
                            for c, name in enumerate(self.classes)}}


def average_precision(recall: np.ndarray, precision: np.ndarray, metric: str = "voc07") -> float:
    """voc_eval's voc_ap: recall / precision in descending-confidence order -> AP."""
    recall, precision = np.asarray(recall, np.float64), np.asarray(precision, np.float64)
    if metric == "voc07":
        ap = 0.0
        for t in VOC07_RECALL_POINTS:  # summed in voc_eval's order, p / 11 at a time
            ap += (precision[recall >= t].max() if np.any(recall >= t) else 0.0) / 11.0
        return float(ap)
    if metric != "all":
        raise ValueError(f"metric must be one of {VOC_METRICS}; got {metric!r}")
    mrec = np.concatenate(([0.0], recall, [1.0]))
    envelope = np.maximum.accumulate(np.concatenate(([0.0], precision, [0.0]))[::-1])[::-1]
    steps = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[steps + 1] - mrec[steps]) * envelope[steps + 1]))


def voc_iou(det: np.ndarray, gt: np.ndarray, convention: str = "edges") -> np.ndarray:
    """(N, 4) x (M, 4) -> (N, M) IoU, voc_eval's expression; "inclusive" adds 1 to every side."""
    one = {"edges": 0.0, "inclusive": 1.0}[convention]
    det, gt = det[:, None, :], gt[None, :, :]
    iw = np.maximum(np.minimum(det[..., 2], gt[..., 2]) - np.maximum(det[..., 0], gt[..., 0]) + one, 0.0)
    ih = np.maximum(np.minimum(det[..., 3], gt[..., 3]) - np.maximum(det[..., 1], gt[..., 1]) + one, 0.0)
    inters = iw * ih
    union = ((det[..., 2] - det[..., 0] + one) * (det[..., 3] - det[..., 1] + one)
             + (gt[..., 2] - gt[..., 0] + one) * (gt[..., 3] - gt[..., 1] + one) - inters)
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero-area pair (edges only) has IoU 0
        return np.where(union > 0, inters / np.where(union > 0, union, 1.0), 0.0)


def _frame_outcomes(iou: np.ndarray, difficult: np.ndarray, order: np.ndarray, iou_threshold: float,
                    strict: bool) -> np.ndarray:
    """One frame, one class: +1 TP, -1 FP, 0 ignored (difficult) per detection, visited in `order`
    (descending score). The frame's "taken" state is all that couples detections, and it stays in
    the frame, so frames can be matched one at a time and merged by score afterwards."""
    outcome = np.zeros(iou.shape[0], np.int8)
    taken = np.zeros(iou.shape[1], bool)
    for d in order:
        if iou.shape[1] == 0:
            outcome[d] = -1
            continue
        best = int(np.argmax(iou[d]))
        if not (iou[d, best] > iou_threshold if strict else iou[d, best] >= iou_threshold):
            outcome[d] = -1
        elif not difficult[best]:
            outcome[d] = -1 if taken[best] else 1
            taken[best] = True
    return outcome


def voc_ap(gts: Mapping[str, Boxes2D], dets: Mapping[str, Boxes2D], classes: Sequence[str], *,
           iou_threshold: float = 0.5, metric: str = "voc07", convention: str = "edges",
           strict: bool = True) -> VocAP:
    """VOC AP per class and mAP over frames (sample id -> Boxes2D; ground truth with difficult flags
    or None, detections with scores). A sample with detections but no ground-truth entry is an error."""
    if metric not in VOC_METRICS or convention not in CONVENTIONS:
        raise ValueError(f"metric must be one of {VOC_METRICS} and convention one of {CONVENTIONS}; "
                         f"got {metric!r}, {convention!r}")
    table = class_table(classes)
    npos = np.zeros(len(table), np.int64)
    labels, scores, outcomes = [], [], []
    for sid, gt, det in paired_frames(gts, dets):
        gt_labels = label_indices(gt, table, f"ground truth of sample {sid!r}")
        det_labels = label_indices(det, table, f"detections of sample {sid!r}")
        det_scores = checked_scores(det, f"detections of sample {sid!r}")
        difficult = np.zeros(len(gt), bool) if gt.difficult is None else np.asarray(gt.difficult, bool)
        npos += np.bincount(gt_labels[~difficult], minlength=len(table))
        iou = voc_iou(checked_boxes(det, f"detections of sample {sid!r}"),
                      checked_boxes(gt, f"ground truth of sample {sid!r}"), convention)
        outcome = np.zeros(len(det), np.int8)
        for c in np.unique(det_labels):
            rows, cols = np.flatnonzero(det_labels == c), np.flatnonzero(gt_labels == c)
            outcome[rows] = _frame_outcomes(iou[np.ix_(rows, cols)], difficult[cols],
                                            score_order(det_scores[rows]), iou_threshold, strict)
        labels.append(det_labels)
        scores.append(det_scores)
        outcomes.append(outcome)
    labels, scores, outcomes = (np.concatenate(x) if x else np.zeros(0, t) for x, t in
                                ((labels, np.int64), (scores, np.float64), (outcomes, np.int8)))
    ap = np.full(len(table), np.nan)
    for c in np.flatnonzero(npos):
        rows = np.flatnonzero(labels == c)
        ranked = outcomes[rows[score_order(scores[rows])]]
        tp, fp = np.cumsum(ranked == 1), np.cumsum(ranked == -1)
        ap[c] = average_precision(tp / npos[c], tp / np.maximum(tp + fp, np.finfo(np.float64).eps), metric)
    return VocAP(tuple(table), ap, npos, np.bincount(labels, minlength=len(table)).astype(np.int64), metric,
                 float(iou_threshold))

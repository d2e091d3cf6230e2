"""The DAROD protocol: the RD-map mAP that DAROD (Decourt et al., IEEE IV 2022) reports, and hence
what the DAROD rows of the YOLOv8n-Adapter paper's Table 2 mean.

Facts from colindecourt/darod (`darod/metrics/mAP.py`, `eval.py`, `darod/models/model.py`,
`config/config_raddet.json`); the code here is ours:

- IoU thresholds 0.1, 0.3, 0.5, 0.7. IoU of (x1, y1, x2, y2) boxes with no "+1" (`iou2d`).
- Per frame, predictions are taken in descending score (the order of DAROD's NMS output). Each is
  compared with its best ground truth of ANY class (argmax of IoU, first index on ties). It is a true
  positive only if its label equals that ground truth's, IoU >= t, and that ground truth was not
  matched before at t; otherwise a false positive. There is no fallback to the next-best ground
  truth, so a prediction that overlaps a neighbour of another class more is a false positive.
- Per class, all frames' predictions are sorted by score; AP is the all-point VOC area under the
  monotone precision envelope (sentinels recall 0 and 1, precision 0), mAP the mean over classes.
- Score threshold and detection cap: `accumulate_tp_fp` applies neither; DAROD's decoder does, at
  inference (tf.image.combined_non_max_suppression: per-class NMS IoU 0.1, keeps scores > 0.5,
  strictly, at most 30 detections per frame over all classes, sorted by score). The detections a
  DAROD row was scored on therefore passed both, so `darod_evaluate` applies them by default
  (score > 0.5, then the 30 best); pass None to switch either off. NMS is the detector's job.
- DAROD's metric drops predictions whose four coordinates are all zero (the NMS output's padding);
  so does this module, after the cap as there.

Our choices where DAROD's code leaves it open (the protocol: docs/range-doppler.md, "Metrics for
2D boxes"):
- Classes: DAROD averages over every configured class (RADDet 6, CARRADA 3), and every one of
  them has ground truth in those test sets. Here a class without ground truth has AP NaN and is
  left out of the mean (DAROD would give 0 without detections of it, NaN with some).
- Ties in score: DAROD sorts with numpy's default (unstable) quicksort; we sort stably, so equal
  scores keep frame order (the ground-truth mapping's order), then rank within the frame.
- Precision: DAROD's IoU is float32 with 1e-10 added to the union, on coordinates normalised to
  [0, 1]; ours is the exact float64 IoU of boxes.boxes2d. They differ only for an IoU equal to a
  threshold (DAROD: a hair below it, a miss; here: a hit, as in pycocotools).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from ...boxes.boxes2d import Boxes2D, pairwise_iou
from .frames import checked_boxes, checked_scores, class_table, label_indices, paired_frames, score_order

DAROD_IOU_THRESHOLDS = (0.1, 0.3, 0.5, 0.7)
DAROD_SCORE_THRESHOLD = 0.5   # config fastrcnn.box_nms_score, kept when score > it
DAROD_MAX_DETECTIONS = 30     # config fastrcnn.frcnn_num_pred (NMS max_total_size)


@dataclasses.dataclass(frozen=True)
class DarodMetrics:
    classes: tuple[str, ...]
    iou_thresholds: tuple[float, ...]
    ap: np.ndarray       # (C, T) all-point AP per class and threshold; NaN for a class without ground truth
    n_gt: np.ndarray     # (C,) ground-truth boxes per class
    map: np.ndarray      # (T,) mean AP over the classes with ground truth (NaN if none has any)

    def map_at(self, iou: float) -> float:
        return float(self.map[self._column(iou)])

    def ap_at(self, name: str, iou: float) -> float:
        return float(self.ap[self.classes.index(name), self._column(iou)])

    def _column(self, iou: float) -> int:
        hits = [i for i, t in enumerate(self.iou_thresholds) if abs(t - iou) < 1e-9]
        if not hits:
            raise ValueError(f"IoU {iou} was not evaluated; thresholds are {self.iou_thresholds}")
        return hits[0]

    def as_dict(self) -> dict[str, float]:
        """'mAP@30' and 'AP@30/<class>' style keys (threshold in percent), values in [0, 1]."""
        out = {f"mAP@{round(100 * t)}": float(m) for t, m in zip(self.iou_thresholds, self.map)}
        for c, name in enumerate(self.classes):
            out.update({f"AP@{round(100 * t)}/{name}": float(a) for t, a in zip(self.iou_thresholds, self.ap[c])})
        return out


def darod_detections(det: Boxes2D, score_threshold: float | None, max_detections: int | None,
                     where: str) -> np.ndarray:
    """Indices of the detections DAROD scores, in the order it scores them. As its decoder (NMS):
    score > threshold, descending score, the first `max_detections`; then, as its metric, boxes
    whose four coordinates are all zero dropped (after the cap, as there)."""
    scores, xyxy = checked_scores(det, where), checked_boxes(det, where)
    keep = np.arange(len(scores))
    if score_threshold is not None:
        keep = keep[scores > score_threshold]
    keep = keep[score_order(scores[keep])]
    if max_detections is not None:
        keep = keep[:max_detections]
    return keep[np.any(xyxy[keep] != 0, axis=1)]


def first_claims(ok: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(N, T) bool: ok[i, t] and no earlier row j < i with the same target has ok[j, t]. With rows
    in DAROD's order this is its "ground truth not yet detected" rule: a ground truth goes to the
    first prediction that qualifies for it, and every later one that picks it is a false positive."""
    tp = np.zeros_like(ok)
    for t in range(ok.shape[1]):
        rows = np.flatnonzero(ok[:, t])
        _, first = np.unique(target[rows], return_index=True)
        tp[rows[first], t] = True
    return tp


def all_point_ap(tp: np.ndarray, n_gt: int) -> np.ndarray:
    """VOC all-point AP per column of tp (N, T), rows in descending score: area under the monotone
    precision envelope with sentinels (recall 0, precision 0) and (recall 1, precision 0)."""
    out = np.zeros(tp.shape[1])
    for t in range(tp.shape[1]):
        tpc = np.cumsum(tp[:, t])
        fpc = np.cumsum(~tp[:, t])
        recall = np.concatenate(([0.0], tpc / n_gt, [1.0]))
        precision = np.concatenate(([0.0], tpc / np.maximum(tpc + fpc, np.finfo(np.float64).eps), [0.0]))
        envelope = np.maximum.accumulate(precision[::-1])[::-1]
        steps = np.flatnonzero(recall[1:] != recall[:-1])
        out[t] = np.sum((recall[steps + 1] - recall[steps]) * envelope[steps + 1])
    return out


def darod_evaluate(gts: Mapping[str, Boxes2D], dets: Mapping[str, Boxes2D], classes: Sequence[str], *,
                   iou_thresholds: Sequence[float] = DAROD_IOU_THRESHOLDS,
                   score_threshold: float | None = DAROD_SCORE_THRESHOLD,
                   max_detections: int | None = DAROD_MAX_DETECTIONS) -> DarodMetrics:
    """DAROD's mAP over frames (sample id -> Boxes2D, ground truth and detections)."""
    table = class_table(classes)
    thresholds = np.asarray(iou_thresholds, np.float64)
    n_gt = np.zeros(len(table), np.int64)
    labels, scores, claims, oks = [], [], [], []
    gt_offset = 0
    for sid, gt, det in paired_frames(gts, dets):
        gt_labels = label_indices(gt, table, f"ground truth of sample {sid!r}")
        n_gt += np.bincount(gt_labels, minlength=len(table))
        keep = darod_detections(det, score_threshold, max_detections, f"detections of sample {sid!r}")
        det_labels = label_indices(det.select(keep), table, f"detections of sample {sid!r}")
        if len(gt_labels) and len(keep):
            iou = pairwise_iou(checked_boxes(det, f"detections of sample {sid!r}")[keep],
                               checked_boxes(gt, f"ground truth of sample {sid!r}"))
            best = np.argmax(iou, axis=1)                        # best ground truth of ANY class
            best_iou = iou[np.arange(len(keep)), best]
            ok = (det_labels == gt_labels[best])[:, None] & (best_iou[:, None] >= thresholds[None])
        else:
            best, ok = np.zeros(len(keep), np.int64), np.zeros((len(keep), len(thresholds)), bool)
        labels.append(det_labels)
        scores.append(np.asarray(det.scores, np.float64)[keep])
        claims.append(gt_offset + best)
        oks.append(ok)
        gt_offset += len(gt_labels)
    labels, scores = np.concatenate(labels or [np.zeros(0, np.int64)]), np.concatenate(scores or [np.zeros(0)])
    claims = np.concatenate(claims or [np.zeros(0, np.int64)])
    tp = first_claims(np.concatenate(oks or [np.zeros((0, len(thresholds)), bool)]), claims)
    ap = np.full((len(table), len(thresholds)), np.nan)
    for c in np.flatnonzero(n_gt):
        rows = np.flatnonzero(labels == c)
        ap[c] = all_point_ap(tp[rows[score_order(scores[rows])]], int(n_gt[c]))
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(ap, axis=0) if n_gt.any() else np.full(len(thresholds), np.nan)
    return DarodMetrics(tuple(table), tuple(float(t) for t in thresholds), ap, n_gt, mean)

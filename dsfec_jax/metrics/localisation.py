"""Localisation error of placed detections: how far, in metres on the ground, a matched detection's
map position lies from its ground-truth object, by range bin.

Matching (per frame, `match_frame`): detections in descending score (ties in input order) each
take the unmatched ground-truth box of the same class with the highest IoU, if that IoU is at
least 0.5; a ground-truth box is matched at most once. This is COCO's greedy rule at one
threshold (VOC's voc_eval instead lets a detection claim an already-matched box and become a
false positive, which matters for AP, not for the position of true positives). IoU is
boxes2d.pairwise_iou on pixel-edge boxes.

Error: the horizontal distance sqrt(dE^2 + dN^2) between the placed position and the object's
true position in one local ENU frame (metres). Bins are of the true range (depth along the
optical axis is the natural choice, the same bins as metrics/depth/per_detection.py: 0-10,
10-20, 20-40, 40+ m, plus 0-40 and all); per bin: count, mean, median and 90th percentile.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..boxes.boxes2d import pairwise_iou
from .boxes2d.frames import score_order
from .depth.per_detection import RANGE_BINS_M, bin_label, range_rows


def match_frame(gt_xyxy, gt_names, det_xyxy, det_names, det_scores, iou_threshold: float = 0.5) -> np.ndarray:
    """(M, 2) int64 [detection index, ground-truth index] of the matched pairs (module docstring)."""
    gt, det = np.asarray(gt_xyxy, np.float64).reshape(-1, 4), np.asarray(det_xyxy, np.float64).reshape(-1, 4)
    gt_names, det_names = np.asarray(gt_names).astype(str), np.asarray(det_names).astype(str)
    scores = np.asarray(det_scores, np.float64).reshape(-1)
    if len(gt_names) != len(gt) or not (len(det_names) == len(scores) == len(det)):
        raise ValueError(f"{len(gt)} ground-truth boxes with {len(gt_names)} names; {len(det)} detections with "
                         f"{len(det_names)} names and {len(scores)} scores: expected one name (and score) per box")
    if not (np.isfinite(gt).all() and np.isfinite(det).all() and np.isfinite(scores).all()):
        raise ValueError("boxes and scores must be finite")
    iou = pairwise_iou(det, gt)
    iou[det_names[:, None] != gt_names[None, :]] = -1.0
    taken = np.zeros(len(gt), bool)
    pairs = []
    for d in score_order(scores):
        cand = np.where(taken, -1.0, iou[d])
        if len(cand) and cand.max() >= iou_threshold:
            g = int(np.argmax(cand))
            taken[g] = True
            pairs.append((int(d), g))
    return np.array(pairs, np.int64).reshape(-1, 2)


def horizontal_errors(pred_enu, true_enu) -> np.ndarray:
    """(N,) metres between (N, 2 or 3) ENU positions, east and north only."""
    p, t = np.asarray(pred_enu, np.float64), np.asarray(true_enu, np.float64)
    if p.shape != t.shape or p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"positions must be matched (N, 2) or (N, 3) arrays; got {p.shape} and {t.shape}")
    return np.hypot(p[:, 0] - t[:, 0], p[:, 1] - t[:, 1])


@dataclasses.dataclass(frozen=True)
class LocalisationRow:
    range_m: str
    count: int
    mean_m: float
    median_m: float
    p90_m: float

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def localisation_table(errors_m, true_range_m, bins=RANGE_BINS_M) -> list[LocalisationRow]:
    """One row per range bin of the matched objects' errors (NaN statistics for an empty bin)."""
    e, r = np.asarray(errors_m, np.float64).reshape(-1), np.asarray(true_range_m, np.float64).reshape(-1)
    if e.shape != r.shape or not np.isfinite(e).all():
        raise ValueError(f"{e.size} errors for {r.size} ranges; expected one finite error per matched object")
    rows = []
    for label, mask in range_rows(r, bins):
        x = e[mask]
        stats = (float(x.mean()), float(np.median(x)), float(np.percentile(x, 90))) if x.size else (math.nan,) * 3
        rows.append(LocalisationRow(label, int(x.size), *stats))
    return rows


def format_localisation_table(rows: list[LocalisationRow]) -> str:
    lines = ["| true range (m) | matched objects | mean (m) | median (m) | p90 (m) |", "|---|---|---|---|---|"]
    lines += [f"| {r.range_m} | {r.count} | {r.mean_m:.2f} | {r.median_m:.2f} | {r.p90_m:.2f} |" for r in rows]
    return "\n".join(lines) + "\n"


__all__ = ["RANGE_BINS_M", "LocalisationRow", "bin_label", "format_localisation_table", "horizontal_errors",
           "localisation_table", "match_frame"]

"""Greedy non-maximum suppression of oriented BEV boxes ``(x, y, w, l, yaw)``, in numpy.

Boxes are visited by descending score; ties go to the lower index, so results are deterministic.
A box is suppressed when its BEV IoU with an already kept box is strictly above the threshold.
"""

from __future__ import annotations

import numpy as np

from dsfec_jax.boxes.rotated_iou import bev_iou


def rotated_nms(boxes, scores, iou_threshold: float, max_output: int | None = None,
                score_threshold: float | None = None, pre_top_k: int | None = None) -> np.ndarray:
    """Indices (int64) of the boxes (M, 5) kept by greedy NMS, highest score first.

    iou_threshold: in [0, 1]; a box whose BEV IoU with a kept box is above it is suppressed.
    score_threshold: only boxes with score > score_threshold take part (NaN scores never do).
    pre_top_k: only the pre_top_k best-scoring of those take part (bounds the cost).
    max_output: stop once this many boxes are kept; the result is a prefix of the unbounded one.
    """
    if not 0.0 <= iou_threshold <= 1.0:
        raise ValueError(f"iou_threshold must lie in [0, 1], got {iou_threshold}")
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    alive = _ranked(np.asarray(scores, np.float64), score_threshold, pre_top_k)
    limit = len(alive) if max_output is None else max_output
    keep = []
    while alive.size and len(keep) < limit:
        best, rest = alive[0], alive[1:]
        keep.append(best)
        # Only the boxes still alive are compared: suppressed ones never suppress anything.
        alive = rest[~_overlaps(boxes[best], boxes[rest], iou_threshold)]
    return np.asarray(keep, np.int64)


def batched_rotated_nms(boxes, scores, labels, iou_threshold: float, max_output: int | None = None,
                        score_threshold: float | None = None, pre_top_k: int | None = None) -> np.ndarray:
    """`rotated_nms` run separately per label: boxes of different classes never suppress each other.

    score_threshold and pre_top_k apply per class; max_output bounds the merged result, which is
    ordered by descending score (ties: lower index first).
    """
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    scores, labels = np.asarray(scores, np.float64), np.asarray(labels)
    kept = [np.zeros(0, np.int64)]
    for label in np.unique(labels):
        idx = np.flatnonzero(labels == label)
        # Passing max_output on is safe: the merged top max_output holds at most that many of any class.
        kept.append(idx[rotated_nms(boxes[idx], scores[idx], iou_threshold, max_output,
                                    score_threshold, pre_top_k)])
    kept = np.concatenate(kept)
    kept = kept[np.lexsort((kept, -scores[kept]))]
    return kept if max_output is None else kept[:max_output]


def _overlaps(box, others, iou_threshold: float) -> np.ndarray:
    """(K,) bool: BEV IoU of box (5,) with others (K, 5) is above the threshold."""
    # IoU <= smaller area / larger area, so pairs of very different sizes need no clipping.
    area = max(box[2], 0.0) * max(box[3], 0.0)
    areas = np.maximum(others[:, 2], 0.0) * np.maximum(others[:, 3], 0.0)
    could = np.minimum(area, areas) > iou_threshold * np.maximum(area, areas)
    out = np.zeros(len(others), bool)
    out[could] = bev_iou(box, others[could])[0] > iou_threshold
    return out


def _ranked(scores, score_threshold, pre_top_k) -> np.ndarray:
    """Indices of the candidate boxes, best score first, ties by index (stable sort)."""
    ok = ~np.isnan(scores)
    if score_threshold is not None:
        ok &= scores > score_threshold
    idx = np.flatnonzero(ok)
    idx = idx[np.argsort(-scores[idx], kind="stable")]
    return idx if pre_top_k is None else idx[:pre_top_k]

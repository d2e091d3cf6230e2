"""Greedy non-maximum suppression of oriented BEV boxes ``(x, y, w, l, yaw)``.

Boxes are visited by descending score; ties go to the lower index, so results are deterministic.
A box is suppressed when its BEV IoU with an already kept box is strictly above the threshold:
every comparison answers exactly as `rotated_iou.bev_iou_aligned(kept box, other box) > threshold`,
so the kept indices are those of the plain greedy pass, not merely close to them.

Ranking and filtering are numpy; the greedy pass itself is one compiled loop
(`nms_kernel.greedy_keep`, numba) with the exact pair IoU in scalar form. Classes never suppress
each other, so one pass in global score order keeps what per-class passes keep, already merged.
On DSFEC-S frames (~300 candidates in 3 classes, ~40 kept) the earlier vectorised numpy version
made ~600 numpy calls a frame; the timings before and after are in docs/points-deploy.md, and
`dsfec bench --models dsfec_s --runtimes jax` prints NMS's time a frame.
"""

from __future__ import annotations

import numpy as np

from dsfec_jax.boxes.nms_kernel import greedy_keep
from dsfec_jax.boxes.rotated_iou import circumradius


def rotated_nms(boxes, scores, iou_threshold: float, max_output: int | None = None,
                score_threshold: float | None = None, pre_top_k: int | None = None) -> np.ndarray:
    """Indices (int64) of the boxes (M, 5) kept by greedy NMS, highest score first.

    iou_threshold: in [0, 1]; a box whose BEV IoU with a kept box is above it is suppressed.
    score_threshold: only boxes with score > score_threshold take part (NaN scores never do).
    pre_top_k: only the pre_top_k best-scoring of those take part (bounds the cost).
    max_output: stop once this many boxes are kept; the result is a prefix of the unbounded one.
    """
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    return batched_rotated_nms(boxes, scores, np.zeros(len(boxes), np.int8), iou_threshold,
                               max_output, score_threshold, pre_top_k)


def batched_rotated_nms(boxes, scores, labels, iou_threshold: float, max_output: int | None = None,
                        score_threshold: float | None = None, pre_top_k: int | None = None) -> np.ndarray:
    """`rotated_nms` run separately per label: boxes of different classes never suppress each other.

    score_threshold and pre_top_k apply per class; max_output bounds the merged result, which is
    ordered by descending score (ties: lower index first).
    """
    boxes, scores, labels = _checked(boxes, scores, labels, iou_threshold, max_output, pre_top_k)
    order = _ranked(scores, labels, score_threshold, pre_top_k)
    if max_output == 0 or len(order) == 0:
        return np.zeros(0, np.int64)
    ranked = np.ascontiguousarray(boxes[order])
    # Label codes (any dtype, NaN-free after _ranked) as small ints for the compiled loop.
    codes = np.unique(labels[order], return_inverse=True)[1].reshape(-1).astype(np.int64)
    radius = circumradius(ranked)
    with np.errstate(invalid="ignore"):  # an infinite yaw: NaN corners; such a box is not live anyway
        cos_yaw, sin_yaw = np.cos(ranked[:, 4]), np.sin(ranked[:, 4])
    area = np.maximum(ranked[:, 2], 0.0) * np.maximum(ranked[:, 3], 0.0)
    # A box with a non-finite centre or size, or no area, overlaps nothing (IoU 0 or NaN).
    live = np.isfinite(ranked[:, 0]) & np.isfinite(ranked[:, 1]) & np.isfinite(radius) & (area > 0)
    kept = greedy_keep(ranked, cos_yaw, sin_yaw, radius, codes, live, float(iou_threshold),
                       -1 if max_output is None else int(max_output))
    return order[kept].astype(np.int64, copy=False)


def _checked(boxes, scores, labels, iou_threshold, max_output, pre_top_k):
    """The inputs as float64 (M, 5) boxes, float64 (M,) scores and (M,) labels, or a clear error."""
    if not 0.0 <= iou_threshold <= 1.0:
        raise ValueError(f"iou_threshold must lie in [0, 1], got {iou_threshold}")
    for name, value in (("max_output", max_output), ("pre_top_k", pre_top_k)):
        if value is not None and value < 0:
            raise ValueError(f"{name} must be None or >= 0, got {value}")
    boxes = np.asarray(boxes, np.float64).reshape(-1, 5)
    scores, labels = np.asarray(scores, np.float64).reshape(-1), np.asarray(labels).reshape(-1)
    if len(scores) != len(boxes) or len(labels) != len(boxes):
        raise ValueError(f"expected one score and one label per box: {len(boxes)} boxes, "
                         f"{len(scores)} scores, {len(labels)} labels")
    return boxes, scores, labels


def _ranked(scores, labels, score_threshold, pre_top_k) -> np.ndarray:
    """Indices of the candidate boxes, best score first, ties by index (stable sort); with
    pre_top_k, only each label's pre_top_k best. A NaN score, or a NaN label (no class: it equals
    nothing, not even itself), never takes part."""
    ok = ~np.isnan(scores) & (labels == labels)
    if score_threshold is not None:
        ok &= scores > score_threshold
    idx = np.flatnonzero(ok)
    idx = idx[np.argsort(-scores[idx], kind="stable")]
    if pre_top_k is None:
        return idx
    # Each label's group lists its positions in score order, so its first pre_top_k are its best.
    best = [group[:pre_top_k] for group in _label_groups(labels[idx])]
    return idx[np.sort(np.concatenate(best))] if best else idx


def _label_groups(labels) -> list[np.ndarray]:
    """Positions of each label's entries, ascending (one group when all labels are equal)."""
    if len(labels) == 0:
        return []
    by_label = np.argsort(labels, kind="stable")
    cuts = np.flatnonzero(labels[by_label][1:] != labels[by_label][:-1]) + 1
    return np.split(by_label, cuts)

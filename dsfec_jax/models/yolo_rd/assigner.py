"""The task-aligned assigner of YOLOv8 (TOOD's TAL as ultralytics runs it), in jax with fixed shapes.

Facts from ultralytics (repo ultralytics/ultralytics, ultralytics/utils/tal.py, TaskAlignedAssigner,
the YOLOv8-era version; v8DetectionLoss builds it with topk 10, alpha 0.5, beta 6), read, not copied.
Everything is in input pixels and carries no gradient. Per image, for GT g and anchor a:

1. candidate(g, a): the anchor centre lies strictly inside the GT box: min(x - x1, y - y1, x2 - x,
   y2 - y) > 1e-9; padded GTs (mask False) have no candidates.
2. overlap(g, a) = max(CIoU(gt_g, pred_a), 0) and score(g, a) = the predicted (sigmoid) score of g's
   class at a, both on candidates only (0 elsewhere); align(g, a) = score^alpha * overlap^beta.
3. top-k: each real GT takes the k anchors of largest align (all anchors compete, ties to the lower
   anchor index: `lax.top_k`; torch.topk leaves tie order unspecified); positives = top-k AND
   candidate. With fewer than k positive-align candidates, zero-align candidates can still be picked.
4. an anchor that is positive for several GTs goes to the GT of largest overlap over *all* GTs
   (argmax over the GT axis of the overlap matrix, first index on ties), as ultralytics'
   select_highest_overlaps does; that GT need not be one of those that picked it.
5. targets: the assigned GT's label and box; target score for class c = one-hot(label) times
   max over GTs of align(g, a) * max_a' overlap(g, a') / (max_a' align(g, a') + 1e-9), the maxima
   over g's positives only; background anchors get zeros.

k is min(topk, number of anchors) (torch.topk would refuse k > A).

Small boxes: a GT narrower than the finest stride may contain no anchor centre at all and then is
never learned (range-Doppler boxes are often a few pixels wide). Recent ultralytics releases (the
`stride` argument of TaskAlignedAssigner; 8.4.190's v8DetectionLoss passes the model's strides, so
stride_val = stride[1] = 16) widen, for the candidate test only, every side of a real GT shorter than
stride_val to stride_val about its centre: `small_side=(16.0, 16.0)`. `(8.0, 16.0)` widens only the
sides under 8 px (the rule the shipped RD weights were trained with); the default None keeps the
YOLOv8-era rule above.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ...boxes.iou2d_jax import bbox_ciou


@dataclasses.dataclass(frozen=True)
class AssignerConfig:
    topk: int = 10
    alpha: float = 0.5
    beta: float = 6.0
    eps: float = 1e-9  # inside-box margin and the normalisation's eps (ultralytics' single eps)
    small_side: tuple[float, float] | None = None  # (below, widened_to) for the candidate test; None: off


class Assignment(NamedTuple):
    labels: jnp.ndarray      # (B, A) int32 >= 0, the assigned GT's label (GT 0's for background)
    boxes: jnp.ndarray       # (B, A, 4) xyxy pixels, the assigned GT's box (GT 0's for background)
    scores: jnp.ndarray      # (B, A, C) soft one-hot targets, zero on background
    foreground: jnp.ndarray  # (B, A) bool
    gt_index: jnp.ndarray    # (B, A) int32, the assigned GT (0 for background)


def candidates_inside(anchor_points, gt_boxes, eps: float = 1e-9,
                      small_side: tuple[float, float] | None = None) -> jnp.ndarray:
    """(B, M, A) bool: anchor centre (A, 2) strictly inside GT box (B, M, 4) by more than eps;
    with small_side = (below, widened_to), sides shorter than `below` count as `widened_to` long."""
    if small_side is not None:
        centre, size = (gt_boxes[..., :2] + gt_boxes[..., 2:]) / 2, gt_boxes[..., 2:] - gt_boxes[..., :2]
        size = jnp.where(size < small_side[0], small_side[1], size)
        gt_boxes = jnp.concatenate([centre - size / 2, centre + size / 2], -1)
    p = anchor_points[None, None]
    g = gt_boxes[:, :, None]
    deltas = jnp.concatenate([p - g[..., :2], g[..., 2:] - p], -1)
    return jnp.min(deltas, -1) > eps


def box_metrics(pred_scores, pred_boxes, gt_labels, gt_boxes, valid, cfg: AssignerConfig):
    """(align, overlap), each (B, M, A), zero outside `valid` (candidate of a real GT)."""
    num_classes = pred_scores.shape[-1]
    labels = jnp.clip(gt_labels, 0, num_classes - 1).astype(jnp.int32)
    score = jnp.take_along_axis(jnp.swapaxes(pred_scores, 1, 2), labels[..., None], axis=1)  # (B, M, A)
    ciou = bbox_ciou(gt_boxes[:, :, None, :], pred_boxes[:, None, :, :])
    overlap = jnp.where(valid, jnp.maximum(ciou, 0.0), 0.0)
    score = jnp.where(valid, score, 0.0)
    return score**cfg.alpha * overlap**cfg.beta, overlap


def select_topk(align, k: int) -> jnp.ndarray:
    """(B, M, A) bool: the k anchors of largest align per GT (ties to the lower anchor index)."""
    _, index = jax.lax.top_k(align, k)
    return jnp.any(jax.nn.one_hot(index, align.shape[-1], dtype=jnp.bool_), axis=-2)


def resolve_multiple_gts(positive, overlap):
    """Anchors positive for several GTs keep only the GT of largest overlap (over all GTs, first
    on ties). Returns (positive (B, M, A), foreground (B, A), gt_index (B, A))."""
    num_gts = positive.shape[1]
    claimed = positive.sum(1)
    best = jax.nn.one_hot(jnp.argmax(overlap, axis=1), num_gts, axis=1, dtype=jnp.bool_)
    positive = jnp.where((claimed > 1)[:, None, :], best, positive)
    return positive, positive.any(1), jnp.argmax(positive, axis=1).astype(jnp.int32)


def assign(pred_scores, pred_boxes, anchor_points, gt_labels, gt_boxes, gt_mask,
           cfg: AssignerConfig = AssignerConfig()) -> Assignment:
    """Task-aligned assignment for a padded batch.

    pred_scores: (B, A, C) class probabilities (sigmoid); pred_boxes: (B, A, 4) xyxy pixels;
    anchor_points: (A, 2) pixels; gt_labels: (B, M) int; gt_boxes: (B, M, 4) xyxy pixels;
    gt_mask: (B, M) bool, False for padding. M may be 0.
    """
    pred_scores, pred_boxes, anchor_points, gt_boxes = (
        jax.lax.stop_gradient(jnp.asarray(x, jnp.float32)) for x in (pred_scores, pred_boxes, anchor_points, gt_boxes))
    gt_labels, gt_mask = jnp.asarray(gt_labels), jnp.asarray(gt_mask, bool)
    batch, anchors, num_classes = pred_scores.shape
    if gt_boxes.shape[1] == 0:  # no GT slot at all: everything is background
        return Assignment(jnp.zeros((batch, anchors), jnp.int32), jnp.zeros((batch, anchors, 4), jnp.float32),
                          jnp.zeros_like(pred_scores), jnp.zeros((batch, anchors), bool),
                          jnp.zeros((batch, anchors), jnp.int32))

    inside = candidates_inside(anchor_points, gt_boxes, cfg.eps, cfg.small_side) & gt_mask[..., None]
    align, overlap = box_metrics(pred_scores, pred_boxes, gt_labels, gt_boxes, inside, cfg)
    positive = select_topk(align, min(cfg.topk, anchors)) & inside
    positive, foreground, gt_index = resolve_multiple_gts(positive, overlap)

    labels = jnp.maximum(jnp.take_along_axis(gt_labels, gt_index, axis=1), 0).astype(jnp.int32)
    boxes = jnp.take_along_axis(gt_boxes, gt_index[..., None], axis=1)
    one_hot = jax.nn.one_hot(labels, num_classes) * foreground[..., None]

    align = jnp.where(positive, align, 0.0)
    best_align = align.max(-1, keepdims=True)                               # (B, M, 1)
    best_overlap = jnp.where(positive, overlap, 0.0).max(-1, keepdims=True)  # (B, M, 1)
    quality = (align * best_overlap / (best_align + cfg.eps)).max(1)         # (B, A)
    return Assignment(labels, boxes, one_hot * quality[..., None], foreground, gt_index)

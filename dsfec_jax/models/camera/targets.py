"""YOLOv3 training targets: padded ground truth (host, numpy) and darknet's anchor assignment (JAX).

Ground truth travels as three fixed-shape arrays per batch, the YOLO-RD family's layout
(data/rd/batches.py), so one compile of the training step serves every batch of a size:
  gt_boxes (B, M, 4) float32: xyxy pixel edges in the network input (boxes/boxes2d.py convention);
  gt_labels (B, M) int32 class ids; gt_mask (B, M) bool, True for real boxes.
M = max_boxes (64 by default; darknet's [yolo] layers reserve 90). An image with more boxes keeps
its M largest (ties: the earlier box), in their original order, and the count of dropped boxes is
returned (darknet keeps a random subset of 90 after shuffling; the house keeps the largest).
`pad_batch` leaves boxes flagged difficult out by default, as darknet's VOC labels do.

The assignment (darknet src/yolo_layer.c, forward_yolo_layer, the truth loop), in input pixels:
1. a box is real when its mask is set, its class id is in [0, C) (darknet skips other ids) and
   both sides are at least `min_side` x the input size (darknet's loader, fill_truth_detection,
   drops boxes under 0.001 of the image);
2. its best anchor is the one of largest shape IoU over all nine (widths and heights only, both
   boxes centred: min(w, aw) min(h, ah) / (w h + aw ah - min(w, aw) min(h, ah))); ties go to the
   lower anchor index (darknet keeps the first strict maximum);
3. only the scale whose mask holds that anchor gets the box, at the cell holding its centre:
   i = floor(cx / stride), j = floor(cy / stride), clipped into the grid (a centre on the right or
   bottom edge of the input falls in the last cell);
4. coordinate targets at that (cell, anchor): x, y offsets in the cell (cx / stride - i) and
   log(w / anchor_w), log(h / anchor_h); coordinate scale 2 - (w / W)(h / H) (darknet's
   2 - truth.w * truth.h with darknet's image-normalised sizes).

Collisions (two real boxes on one cell and anchor of a scale), as darknet resolves them: the later
box in the padded order wins the coordinate targets (darknet overwrites the deltas in truth
order); objectness is positive once; the class target is the union of their classes (darknet's
delta_yolo_class sets the new class to 1 and keeps the earlier one's 1 when the cell was already
hit). Darknet's loader shuffles the boxes, so "later" is random there; here it is the data's order.
Scatters use `max` (winner = largest box index), which is deterministic in XLA.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .anchors import YOLOV3_ANCHORS, Anchors

DEFAULT_MAX_BOXES = 64
MIN_SIDE = 0.001  # fraction of the input size under which darknet's loader drops a box


# --------------------------------------------------------------------------------------------- host


def class_ids(names: Sequence[str], class_names: Sequence[str]) -> np.ndarray:
    """Class names -> int32 ids in class_names; ValueError for a name it does not hold."""
    index = {str(n): k for k, n in enumerate(class_names)}
    unknown = sorted({str(n) for n in names} - set(index))
    if unknown:
        raise ValueError(f"unknown class names {unknown}; known: {list(class_names)}")
    return np.asarray([index[str(n)] for n in names], np.int32).reshape(-1)


def pad_ground_truth(xyxy, labels, max_boxes: int = DEFAULT_MAX_BOXES):
    """One image's boxes (K, 4) xyxy input pixels and class ids (K,) -> (gt_boxes (M, 4),
    gt_labels (M,), gt_mask (M,), dropped) with M = max_boxes; with K > M the M largest stay."""
    xyxy = np.asarray(xyxy, np.float32).reshape(-1, 4)
    labels = np.asarray(labels, np.int32).reshape(-1)
    if len(labels) != len(xyxy):
        raise ValueError(f"{len(xyxy)} boxes but {len(labels)} labels")
    keep = np.arange(len(xyxy))
    if len(keep) > max_boxes:
        area = np.prod(np.clip(xyxy[:, 2:] - xyxy[:, :2], 0, None), axis=1)
        keep = np.sort(np.argsort(-area, kind="stable")[:max_boxes])
    gt_boxes = np.zeros((max_boxes, 4), np.float32)
    gt_labels = np.zeros((max_boxes,), np.int32)
    gt_mask = np.zeros((max_boxes,), bool)
    gt_boxes[: len(keep)], gt_labels[: len(keep)], gt_mask[: len(keep)] = xyxy[keep], labels[keep], True
    return gt_boxes, gt_labels, gt_mask, len(xyxy) - len(keep)


def pad_batch(per_image, class_names: Sequence[str], max_boxes: int = DEFAULT_MAX_BOXES,
              skip_difficult: bool = True) -> tuple[dict, int]:
    """Boxes2D-like ground truth per image (`.xyxy` in input pixels, `.names`, optional
    `.difficult`) -> ({'gt_boxes', 'gt_labels', 'gt_mask'} stacked over the batch, boxes dropped
    for want of slots). skip_difficult: boxes flagged difficult are left out, as darknet's
    scripts/voc_label.py leaves them out of its training labels."""
    if not per_image:
        raise ValueError("pad_batch needs at least one image")
    rows = []
    for b in per_image:
        flags = getattr(b, "difficult", None)
        keep = ~np.asarray(flags, bool) if skip_difficult and flags is not None else np.ones(len(b.names), bool)
        labels = class_ids(np.asarray(b.names)[keep], class_names)
        rows.append(pad_ground_truth(np.asarray(b.xyxy).reshape(-1, 4)[keep], labels, max_boxes))
    arrays = {key: np.stack([r[k] for r in rows]) for k, key in enumerate(("gt_boxes", "gt_labels", "gt_mask"))}
    return arrays, sum(r[3] for r in rows)


# ---------------------------------------------------------------------------------------------- jax


class ScaleTargets(NamedTuple):
    """One output scale's targets, laid out as its output (B, h, w, A, ...)."""
    positive: jnp.ndarray     # (B, h, w, A) bool: a real box is assigned here
    coords: jnp.ndarray       # (B, h, w, A, 4): x, y offsets in the cell, log(w / aw), log(h / ah); 0 elsewhere
    coord_scale: jnp.ndarray  # (B, h, w, A): 2 - (w / W)(h / H) of the assigned box; 0 elsewhere
    classes: jnp.ndarray      # (B, h, w, A, C) float32: union of the assigned boxes' one-hots
    gt_index: jnp.ndarray     # (B, h, w, A) int32: the winning box (the coordinates' source); -1 elsewhere


def real_boxes(gt_boxes, gt_labels, gt_mask, input_hw, num_classes: int, min_side: float = MIN_SIDE):
    """(B, M) bool: padded slots, out-of-range class ids and boxes thinner than min_side x the
    input size are not real."""
    wh = gt_boxes[..., 2:] - gt_boxes[..., :2]
    big = (wh[..., 0] >= min_side * input_hw[1]) & (wh[..., 1] >= min_side * input_hw[0])
    return gt_mask.astype(bool) & big & (gt_labels >= 0) & (gt_labels < num_classes)


def shape_iou(wh, sizes) -> jnp.ndarray:
    """IoU of boxes (..., 2) with anchors (K, 2), both centred at one point -> (..., K)."""
    inter = jnp.prod(jnp.minimum(wh[..., None, :], sizes), -1)
    return inter / (jnp.prod(wh, -1)[..., None] + jnp.prod(sizes, -1) - inter)


def best_anchors(wh, anchors: Anchors = YOLOV3_ANCHORS) -> jnp.ndarray:
    """(...,) int32: the anchor of largest shape IoU over all of them (first on ties)."""
    return jnp.argmax(shape_iou(jnp.asarray(wh, jnp.float32), jnp.asarray(anchors.array())), -1).astype(jnp.int32)


def build_targets(gt_boxes, gt_labels, gt_mask, input_hw: tuple[int, int], num_classes: int,
                  anchors: Anchors = YOLOV3_ANCHORS, min_side: float = MIN_SIDE) -> tuple[ScaleTargets, ...]:
    """Padded ground truth (B, M, ...) -> one ScaleTargets per output scale, in stride order.
    input_hw and num_classes are static; no gradient flows into the targets."""
    gt_boxes = jax.lax.stop_gradient(jnp.asarray(gt_boxes, jnp.float32))
    gt_labels = jnp.asarray(gt_labels, jnp.int32)
    real = real_boxes(gt_boxes, gt_labels, jnp.asarray(gt_mask), input_hw, num_classes, min_side)
    best = best_anchors(gt_boxes[..., 2:] - gt_boxes[..., :2], anchors)
    return tuple(_scale_targets(gt_boxes, gt_labels, real, best, input_hw, num_classes, anchors, s)
                 for s in range(len(anchors.strides)))


def _scale_targets(gt_boxes, gt_labels, real, best, input_hw, num_classes, anchors: Anchors, s: int):
    stride, mask = anchors.strides[s], jnp.asarray(anchors.masks[s])
    (h, w), per = (input_hw[0] // stride, input_hw[1] // stride), anchors.per_scale
    batch, boxes = gt_boxes.shape[:2]
    slots = h * w * per

    hit = best[..., None] == mask                                   # (B, M, A)
    mine = real & hit.any(-1)
    centre = (gt_boxes[..., :2] + gt_boxes[..., 2:]) / 2
    i = jnp.clip(jnp.floor(centre[..., 0] / stride), 0, w - 1).astype(jnp.int32)
    j = jnp.clip(jnp.floor(centre[..., 1] / stride), 0, h - 1).astype(jnp.int32)
    flat = jnp.where(mine, (j * w + i) * per + jnp.argmax(hit, -1), slots)  # `slots`: dropped by the scatter
    rows = jnp.arange(batch)[:, None]

    winner = jnp.zeros((batch, slots), jnp.int32).at[rows, flat].max(
        jnp.broadcast_to(jnp.arange(1, boxes + 1, dtype=jnp.int32), (batch, boxes)), mode="drop")
    classes = jnp.zeros((batch, slots, num_classes), jnp.float32).at[rows, flat, gt_labels].max(1.0, mode="drop")
    positive, gt_index = winner > 0, winner - 1

    box = jnp.take_along_axis(gt_boxes, jnp.clip(gt_index, 0)[..., None], axis=1)  # (B, slots, 4)
    slot = jnp.arange(slots)
    cell = jnp.stack([(slot // per) % w, slot // per // w], -1).astype(jnp.float32)  # (slots, 2): i, j
    size = jnp.where(positive[..., None], box[..., 2:] - box[..., :2], 1.0)
    offset = (box[..., :2] + box[..., 2:]) / 2 / stride - cell
    log_wh = jnp.log(size / jnp.asarray(anchors.for_scale(s))[slot % per])
    coords = jnp.where(positive[..., None], jnp.concatenate([offset, log_wh], -1), 0.0)
    coord_scale = jnp.where(positive, 2.0 - size[..., 0] * size[..., 1] / (input_hw[0] * input_hw[1]), 0.0)

    grid = (batch, h, w, per)
    return ScaleTargets(positive.reshape(grid), coords.reshape(grid + (4,)), coord_scale.reshape(grid),
                        classes.reshape(grid + (num_classes,)), jnp.where(positive, gt_index, -1).reshape(grid))

"""darknet's YOLOv3 loss (src/yolo_layer.c, forward_yolo_layer with the MSE box loss of
yolov3-voc.cfg) in JAX: static shapes, padded ground truth, one compile per input size.

Facts from pjreddie/darknet src/yolo_layer.c, read, not copied. Per output scale, for every cell
and anchor, with p = sigmoid of the raw outputs:
- objectness: darknet's delta is (0 - p_obj) everywhere, zeroed where the decoded prediction's
  best IoU with any real box of its image is > ignore_thresh (strict; 0.5 in yolov3-voc.cfg), then
  set to (1 - p_obj) at assigned anchors (targets.py), which win over the ignore rule;
- classes at assigned anchors: (onehot - p_cls) per class (delta_yolo_class; union on collisions);
- coordinates at assigned anchors (delta_yolo_box): scale (tx - p_x), scale (ty - p_y),
  scale (tw - w_raw), scale (th - h_raw), scale = 2 - w h (sizes as fractions of the input).
darknet applies its deltas as the negative gradients with respect to the raw outputs (its
backward pass does not multiply by the logistic's slope), which makes objectness and classes
exactly binary cross-entropy with logits. For the boxes this module uses the squared errors
  coord = sum scale [(tx - p_x)^2 + (ty - p_y)^2 + (tw - w_raw)^2 + (th - h_raw)^2]
(the form PyTorch ports use and darknet's logged cost sums): for w, h its gradient is 2x darknet's
delta; for x, y it carries the sigmoid's slope p (1 - p) that darknet leaves out.

Reduction: every part is summed over cells, anchors, classes and the batch, then divided by the
batch size (darknet sums over the batch, PyTorch ports divide by it so the learning rate does not
depend on the batch). total = coord_gain (xy + wh) + obj_gain obj + cls_gain cls, all gains 1
(darknet's yolov3-voc.cfg weighs the three parts equally). The ignore IoU and all targets carry no
gradient. Padded, thin (targets.MIN_SIDE) and out-of-range-class boxes are not real: they neither
get anchors nor cause ignores, so a batch with no real box at all gives pure background loss.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp

from ...boxes.iou2d_jax import pairwise_iou
from .anchors import YOLOV3_ANCHORS, Anchors
from .decode import decode_scale, input_size
from .targets import MIN_SIDE, ScaleTargets, build_targets, real_boxes

IGNORE_THRESH = 0.5  # yolov3-voc.cfg (yolov3.cfg, the COCO one, uses 0.7)


@dataclasses.dataclass(frozen=True)
class Yolo3LossConfig:
    ignore_thresh: float = IGNORE_THRESH
    coord_gain: float = 1.0
    obj_gain: float = 1.0
    cls_gain: float = 1.0
    anchors: Anchors = YOLOV3_ANCHORS
    min_side: float = MIN_SIDE


def bce_with_logits(logits, targets) -> jnp.ndarray:
    """Elementwise binary cross-entropy of sigmoid(logits) against targets, stable form."""
    return jnp.maximum(logits, 0.0) - logits * targets + jnp.log1p(jnp.exp(-jnp.abs(logits)))


def best_iou_with_truth(pred_xyxy, gt_boxes, real) -> jnp.ndarray:
    """(B, N) best plain IoU of each predicted box (B, N, 4) with the real boxes (B, M, 4) of its
    image; 0 when the image has none."""
    iou = jax.vmap(pairwise_iou)(pred_xyxy, gt_boxes)  # (B, N, M)
    return jnp.max(jnp.where(real[:, None, :], iou, 0.0), axis=-1, initial=0.0)


def scale_loss(raw, targets: ScaleTargets, gt_boxes, real, anchors: Anchors, s: int, ignore_thresh: float):
    """One scale's sums over the batch: {'xy', 'wh', 'obj', 'cls', 'ignored'}."""
    raw = raw.astype(jnp.float32)
    batch = raw.shape[0]
    pred, _, _ = decode_scale(jax.lax.stop_gradient(raw), anchors, s)            # (B, h, w, A, 4) xyxy
    best = best_iou_with_truth(pred.reshape(batch, -1, 4), gt_boxes, real).reshape(pred.shape[:-1])
    positive = targets.positive
    negative = ~positive & ~(best > ignore_thresh)

    scale = targets.coord_scale[..., None]
    xy = (scale * (targets.coords[..., :2] - jax.nn.sigmoid(raw[..., :2])) ** 2).sum()
    wh = (scale * (targets.coords[..., 2:] - raw[..., 2:4]) ** 2).sum()
    obj_logit = raw[..., 4]
    obj = (jnp.where(positive, bce_with_logits(obj_logit, 1.0), 0.0)
           + jnp.where(negative, bce_with_logits(obj_logit, 0.0), 0.0)).sum()
    cls = jnp.where(positive[..., None], bce_with_logits(raw[..., 5:], targets.classes), 0.0).sum()
    ignored = (~positive & ~negative).sum()
    return {"xy": xy, "wh": wh, "obj": obj, "cls": cls, "ignored": ignored}


def yolo3_loss(outputs: Sequence[jnp.ndarray], gt_boxes, gt_labels, gt_mask,
               cfg: Yolo3LossConfig = Yolo3LossConfig()):
    """(total, parts) for raw outputs [(B, H/s, W/s, A, 5 + C) per stride s, in stride order] and
    padded ground truth gt_boxes (B, M, 4) xyxy input pixels, gt_labels (B, M), gt_mask (B, M).

    parts: 'xy', 'wh', 'obj', 'cls' (per image, gains applied: total is their sum), and
    'positives' / 'ignored' (anchors in the batch). Jit with cfg static: the input size comes from
    the output shapes, so each input size compiles once."""
    input_hw = input_size(outputs, cfg.anchors)
    num_classes = int(outputs[0].shape[-1]) - 5
    batch = outputs[0].shape[0]
    gt_boxes = jax.lax.stop_gradient(jnp.asarray(gt_boxes, jnp.float32))
    real = real_boxes(gt_boxes, jnp.asarray(gt_labels), jnp.asarray(gt_mask), input_hw, num_classes, cfg.min_side)
    targets = build_targets(gt_boxes, gt_labels, gt_mask, input_hw, num_classes, cfg.anchors, cfg.min_side)

    sums = [scale_loss(raw, t, gt_boxes, real, cfg.anchors, s, cfg.ignore_thresh)
            for s, (raw, t) in enumerate(zip(outputs, targets))]
    total = {key: sum(part[key] for part in sums) for key in sums[0]}
    gains = {"xy": cfg.coord_gain, "wh": cfg.coord_gain, "obj": cfg.obj_gain, "cls": cfg.cls_gain}
    parts = {key: gain * total[key] / batch for key, gain in gains.items()}
    parts["positives"] = sum(t.positive.sum() for t in targets).astype(jnp.float32)
    parts["ignored"] = total["ignored"].astype(jnp.float32)
    return sum(parts[key] for key in gains), parts

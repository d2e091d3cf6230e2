"""From YOLOv3's raw outputs to boxes and class-specific scores (JAX), then to detections per
image (host: threshold, per-class NMS, top-k, back to the original image size).

Facts from pjreddie/darknet (src/yolo_layer.c get_yolo_box / get_yolo_detections, src/box.c
do_nms_sort, examples/detector.c validate_detector), read, not copied. Output s is
(B, H/stride, W/stride, A, 5 + C), last axis [tx, ty, tw, th, objectness logit, C class logits];
at column i, row j, anchor k (width aw, height ah from anchors.py), in input pixels:
  b_x = (i + sigmoid(tx)) stride,  b_y = (j + sigmoid(ty)) stride,
  b_w = aw exp(tw),  b_h = ah exp(th),  box = (b_x -+ b_w / 2, b_y -+ b_h / 2) as xyxy pixel edges;
  score[c] = sigmoid(obj) sigmoid(cls_c)  (darknet's class-specific probability).
Candidates run scale by scale in stride order, then row-major (j, i), then anchor: the order of
`output.reshape(B, -1, 5 + C)`, so N = sum over scales of h w A (10,647 at 416 x 416).

Host post-processing (darknet's evaluation settings): a candidate is kept for class c when
score[c] > score_threshold (0.005: validate_detector's threshold for mAP, low so the precision-
recall curve reaches far; darknet's objectness test `obj > thresh` is implied since cls <= 1);
then per-class greedy NMS at IoU > 0.45 (do_nms_sort: per class, by descending score, a kept box
removes the later ones of its class that overlap it; boxes/nms2d.py keeps the same boxes, with
stable ties), one anchor may give several classes; then the max_detections (300) best. darknet
keeps every survivor and has no pre-NMS cap; here only the pre_top_k (30,000, ultralytics'
max_nms) best candidates enter NMS. Both caps matter only for untrained networks, whose scores
all pass 0.005 (212,940 candidates at 416 with 20 classes; the time per image with and without
the cap: docs/camera.md); a trained one leaves a few thousand.

Back to the image: boxes are in network-input pixels; `rescale` maps them to the original image
as input = original x scale + offset, per image. Plain resize (what the camera pipeline feeds):
scale = (W / w0, H / h0), offset 0. Letterbox (darknet's letterbox_image, integer sizes): the
image scaled by min(W / w0, H / h0) and centred, grey bars around it. Boxes are clipped to
[0, w0] x [0, h0] (pixel edges, no +1: boxes/boxes2d.py; VOC's 1-based inclusive XML is the
metric's business).
"""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ...boxes.boxes2d import Boxes2D
from ...boxes.nms2d import MAX_NMS, detect_host
from .anchors import YOLOV3_ANCHORS, Anchors

EVAL_SCORE, NMS_IOU, MAX_DETECTIONS = 0.005, 0.45, 300


def input_size(outputs: Sequence[jnp.ndarray], anchors: Anchors = YOLOV3_ANCHORS) -> tuple[int, int]:
    """(H, W) of the network input, read from the output shapes; ValueError when they disagree."""
    if len(outputs) != len(anchors.strides):
        raise ValueError(f"{len(outputs)} outputs for strides {anchors.strides}")
    h, w = int(outputs[0].shape[1]) * anchors.strides[0], int(outputs[0].shape[2]) * anchors.strides[0]
    for out, stride in zip(outputs, anchors.strides):
        expect = (outputs[0].shape[0], h // stride, w // stride, anchors.per_scale, outputs[0].shape[-1])
        if tuple(out.shape) != expect or out.shape[-1] < 6:
            raise ValueError(f"outputs {[tuple(o.shape) for o in outputs]} do not fit an input of {h} x {w} "
                             f"with strides {anchors.strides}, {anchors.per_scale} anchors and 5 + C channels")
    return h, w


def decode_scale(raw, anchors: Anchors, s: int):
    """Output s (B, h, w, A, 5 + C) -> (boxes (B, h, w, A, 4) xyxy input pixels, objectness (B, h, w, A),
    class probabilities (B, h, w, A, C)), all after the sigmoid / exp."""
    raw = raw.astype(jnp.float32)
    stride = anchors.strides[s]
    h, w = raw.shape[1], raw.shape[2]
    cell = jnp.stack(jnp.meshgrid(jnp.arange(w), jnp.arange(h), indexing="xy"), -1)[:, :, None, :]  # (h, w, 1, 2): i, j
    centre = (cell + jax.nn.sigmoid(raw[..., :2])) * stride
    size = jnp.asarray(anchors.for_scale(s)) * jnp.exp(raw[..., 2:4])
    boxes = jnp.concatenate([centre - size / 2, centre + size / 2], -1)
    return boxes, jax.nn.sigmoid(raw[..., 4]), jax.nn.sigmoid(raw[..., 5:])


def decode(outputs: Sequence[jnp.ndarray], anchors: Anchors = YOLOV3_ANCHORS):
    """Raw outputs -> every candidate: boxes (B, N, 4) xyxy input pixels, scores (B, N, C) =
    sigmoid(obj) sigmoid(cls). Jit-able (anchors static)."""
    input_size(outputs, anchors)
    boxes, scores = [], []
    for s, raw in enumerate(outputs):
        b, obj, cls = decode_scale(raw, anchors, s)
        boxes.append(b.reshape(b.shape[0], -1, 4))
        scores.append((obj[..., None] * cls).reshape(b.shape[0], -1, cls.shape[-1]))
    return jnp.concatenate(boxes, 1), jnp.concatenate(scores, 1)


# --------------------------------------------------------------------------------------------- host


def resize_transform(input_hw, image_hw) -> tuple[np.ndarray, np.ndarray]:
    """(scale (sx, sy), offset (ox, oy)) with input = image x scale + offset for a plain resize."""
    return np.array([input_hw[1] / image_hw[1], input_hw[0] / image_hw[0]]), np.zeros(2)


def letterbox_transform(input_hw, image_hw) -> tuple[np.ndarray, np.ndarray]:
    """The same for darknet's letterbox_image: the longer side fills the input, integer sizes and
    integer centring offsets."""
    (net_h, net_w), (h, w) = input_hw, image_hw
    if net_w / w < net_h / h:
        new_w, new_h = net_w, (h * net_w) // w
    else:
        new_w, new_h = (w * net_h) // h, net_h
    return np.array([new_w / w, new_h / h]), np.array([(net_w - new_w) // 2, (net_h - new_h) // 2], float)


def rescale(xyxy, scale, offset, image_hw) -> np.ndarray:
    """Boxes (K, 4) in input pixels -> original-image pixels, clipped to the image."""
    xyxy = (np.asarray(xyxy, np.float64).reshape(-1, 4) - np.tile(offset, 2)) / np.tile(scale, 2)
    return np.clip(xyxy, 0.0, np.tile([image_hw[1], image_hw[0]], 2)).astype(np.float32)


def detections(boxes, scores, class_names: Sequence[str], image_sizes=None, input_hw=None,
               letterbox: bool = False, score_threshold: float = EVAL_SCORE, iou_threshold: float = NMS_IOU,
               max_detections: int = MAX_DETECTIONS, pre_top_k: int | None = MAX_NMS) -> list[Boxes2D]:
    """Decoded candidates (B, N, 4), (B, N, C) -> one Boxes2D (with scores, highest first) per image.
    image_sizes: (h, w) per image to map back to (needs input_hw, the network input (H, W));
    None leaves the boxes in input pixels."""
    boxes, scores = np.asarray(boxes, np.float32), np.asarray(scores, np.float32)
    names = np.asarray(list(class_names))
    if scores.shape[-1] != len(names):
        raise ValueError(f"{scores.shape[-1]} class scores but {len(names)} class names")
    if image_sizes is not None and (input_hw is None or len(image_sizes) != len(boxes)):
        raise ValueError("image_sizes needs input_hw and one (h, w) per image")
    transform = letterbox_transform if letterbox else resize_transform
    out = []
    for k in range(len(boxes)):
        xyxy, kept_scores, labels = detect_host(boxes[k], scores[k], iou_threshold, score_threshold, max_detections,
                                                multi_label=True, pre_top_k=pre_top_k)
        if image_sizes is not None:
            xyxy = rescale(xyxy, *transform(input_hw, image_sizes[k]), image_sizes[k])
        out.append(Boxes2D(np.asarray(xyxy, np.float32).reshape(-1, 4), names[labels],
                           np.asarray(kept_scores, np.float32)))
    return out

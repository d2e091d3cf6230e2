"""The YOLO-RD post-processing on the host, for decoded outputs (boxes (B, A, 4) xyxy input pixels,
class scores (B, A, nc)): class-aware multi-label greedy NMS (boxes/nms2d.detect_host, the same
boxes as the compiled decode.detect) or YOLOv10's NMS-free top-k (the host twin of
decode_v10.top_detections), padded to max_detections like the compiled versions.

Why the host: after the confidence cut (0.001) a trained model leaves few candidates, and the host
NMS visits only those, while the fixed-shape compiled NMS visits all of them (2016 at 256 x 64 with
six classes), and in ONNX Runtime the compiled loop is slower still (modalities/rd/export.py; the
timings: docs/range-doppler.md, "Deploy"; `dsfec bench --models yolov8n --runtimes jax,onnx --threads 1`
prints both NMS stages).
"""

from __future__ import annotations

import numpy as np

from ...boxes.nms2d import detect_host

NMS, TOP_K = "nms", "top_k"   # the two post-processing kinds: YOLOv8/v9 NMS, YOLOv10's one-to-one top-k


def top_detections_host(boxes, class_scores, score_threshold: float, max_detections: int):
    """decode_v10.top_detections on the host, for one image: the k = min(max_detections, A) anchors
    of largest best-class score, then the k largest of their k x nc scores (ties: lower index first,
    as lax.top_k), those above score_threshold -> (boxes (K, 4), scores (K,), labels (K,))."""
    anchors, num_classes = class_scores.shape
    k = min(max_detections, anchors)
    anchor_index = np.argsort(-class_scores.max(-1), kind="stable")[:k]
    flat_scores = class_scores[anchor_index].reshape(-1)
    flat = np.argsort(-flat_scores, kind="stable")[:k]
    scores = flat_scores[flat]
    keep = scores > score_threshold
    chosen, labels = anchor_index[flat // num_classes], flat % num_classes
    return boxes[chosen][keep], scores[keep], labels[keep]


def host_detections(boxes, class_scores, kind: str, iou_threshold: float, score_threshold: float,
                    max_detections: int) -> tuple[np.ndarray, ...]:
    """Decoded outputs (B, A, 4) and (B, A, nc) -> per image, padded to max_detections like the
    compiled post-processing: boxes (B, K, 4), scores (B, K), labels (B, K) int32, valid (B, K)."""
    if kind not in (NMS, TOP_K):
        raise ValueError(f"postprocess kind {kind!r}; expected {NMS!r} or {TOP_K!r}")
    n = len(boxes)
    out = (np.zeros((n, max_detections, 4), np.float32), np.zeros((n, max_detections), np.float32),
           np.zeros((n, max_detections), np.int32), np.zeros((n, max_detections), bool))
    for i in range(n):
        if kind == NMS:  # pre_top_k None: every candidate, as decode.detect compiles it
            kept = detect_host(boxes[i], class_scores[i], iou_threshold, score_threshold, max_detections,
                               multi_label=True, pre_top_k=None)
        else:
            kept = top_detections_host(boxes[i], class_scores[i], score_threshold, max_detections)
        count = len(kept[1])
        for array, values in zip(out, kept + (np.ones(count, bool),)):
            array[i, :count] = values
    return out

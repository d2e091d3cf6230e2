"""YOLOv3 decoding (models/camera/decode.py): the inverse round trip, candidate order, class-specific
scores, darknet's per-class NMS transcribed, thresholds, top-k and the way back to the image."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.boxes.boxes2d import Boxes2D, pairwise_iou
from dsfec_jax.models.camera.anchors import YOLOV3_ANCHORS
from dsfec_jax.models.camera.decode import (EVAL_SCORE, NMS_IOU, decode, detections, input_size,
                                            letterbox_transform, rescale, resize_transform)

decode_jit = jax.jit(decode)
STRIDES = (8, 16, 32)


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def candidate_index(hw, s, j, i, k):
    """Where (scale s, row j, column i, anchor k) lands among the N candidates."""
    before = sum((hw[0] // t) * (hw[1] // t) * 3 for t in STRIDES[:s])
    return before + (j * (hw[1] // STRIDES[s]) + i) * 3 + k


def encode(boxes_at, hw, classes, rng):
    """The inverse of the decode: raw outputs (noise elsewhere) whose candidate at each
    (s, j, i, k) -> xyxy decodes to that box; the box centre must lie inside cell (i, j)."""
    outputs = [rng.normal(size=(1, hw[0] // t, hw[1] // t, 3, 5 + classes)).astype(np.float32) for t in STRIDES]
    for (s, j, i, k), (x1, y1, x2, y2) in boxes_at.items():
        stride, (aw, ah) = STRIDES[s], YOLOV3_ANCHORS.for_scale(s)[k]
        fx, fy = (x1 + x2) / 2 / stride - i, (y1 + y2) / 2 / stride - j
        assert 0 < fx < 1 and 0 < fy < 1
        outputs[s][0, j, i, k, :4] = [math.log(fx / (1 - fx)), math.log(fy / (1 - fy)),
                                      math.log((x2 - x1) / aw), math.log((y2 - y1) / ah)]
    return [jnp.asarray(o) for o in outputs]


def test_decode_inverts_the_encoding():
    hw, rng = (96, 128), np.random.default_rng(0)
    boxes_at = {(0, 5, 7, 0): (50.0, 41.0, 71.0, 49.0), (1, 3, 3, 2): (30.5, 10.0, 77.5, 90.0),
                (2, 0, 3, 1): (70.0, -60.0, 160.0, 100.0), (2, 2, 0, 2): (-100.0, 5.0, 130.0, 150.0)}
    boxes, scores = decode_jit(encode(boxes_at, hw, 4, rng))
    assert boxes.shape == (1, 3 * (12 * 16 + 6 * 8 + 3 * 4), 4) and scores.shape == boxes.shape[:2] + (4,)
    for where, box in boxes_at.items():
        np.testing.assert_allclose(np.asarray(boxes[0, candidate_index(hw, *where)]), box, rtol=1e-5, atol=1e-4)


def test_decode_is_darknets_formula_and_scores_are_class_specific():
    """b_x = (i + sigmoid(tx)) stride, b_w = aw exp(tw) for every candidate; score = sigmoid(obj)
    sigmoid(cls); jit and eager agree; N = 10,647 at 416 x 416."""
    hw, rng = (64, 96), np.random.default_rng(1)
    outputs = [jnp.asarray(rng.normal(size=(2, hw[0] // t, hw[1] // t, 3, 7)), jnp.float32) for t in STRIDES]
    boxes, scores = decode_jit(outputs)
    for s, raw in enumerate(outputs):
        raw, stride = np.asarray(raw, np.float64), STRIDES[s]
        for b, j, i, k in [(0, 0, 0, 0), (1, raw.shape[1] - 1, raw.shape[2] - 1, 2), (1, 1, 2, 1)]:
            r, (aw, ah) = raw[b, j, i, k], YOLOV3_ANCHORS.for_scale(s)[k]
            cx, cy = (i + sigmoid(r[0])) * stride, (j + sigmoid(r[1])) * stride
            w, h = aw * math.exp(r[2]), ah * math.exp(r[3])
            n = candidate_index(hw, s, j, i, k)
            np.testing.assert_allclose(np.asarray(boxes[b, n]), [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2],
                                       rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(np.asarray(scores[b, n]), sigmoid(r[4]) * sigmoid(r[5:]), rtol=1e-5)
    eager = decode(outputs)
    np.testing.assert_allclose(np.asarray(eager[0]), np.asarray(boxes), rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(np.asarray(eager[1]), np.asarray(scores), rtol=1e-6)
    shapes = jax.eval_shape(decode, [jax.ShapeDtypeStruct((1, 416 // t, 416 // t, 3, 25), jnp.float32)
                                     for t in STRIDES])
    assert shapes[0].shape == (1, 10647, 4) and shapes[1].shape == (1, 10647, 20)


def test_input_size_is_read_from_the_outputs_and_checked():
    outs = [jnp.zeros((2, 320 // t, 480 // t, 3, 8)) for t in STRIDES]
    assert input_size(outs) == (320, 480)
    with pytest.raises(ValueError, match="do not fit"):
        input_size([outs[0], outs[1], jnp.zeros((2, 10, 16, 3, 8))])
    with pytest.raises(ValueError, match="do not fit"):
        input_size([o[..., :2, :] for o in outs])
    with pytest.raises(ValueError, match="outputs for strides"):
        decode(outs[:2])


# --------------------------------------------------------------------------------------------- host


def darknet_nms(boxes, scores, thresh, nms):
    """darknet's validate path transcribed: probabilities <= thresh are 0; per class, by descending
    probability, a non-zero box zeroes that class in the later boxes of IoU > nms; what is left
    (box, class) with probability > 0 -> a set of (candidate, class)."""
    probs = np.where(scores > thresh, scores, 0.0).astype(np.float64)
    for c in range(scores.shape[1]):
        order = np.argsort(-probs[:, c], kind="stable")
        for a, i in enumerate(order):
            if probs[i, c] == 0:
                continue
            for j in order[a + 1:]:
                if pairwise_iou(boxes[i], boxes[j])[0, 0] > nms:
                    probs[j, c] = 0.0
    return {(int(n), int(c)) for n, c in np.argwhere(probs > 0)}


def test_host_detections_are_darknets_per_class_nms():
    rng = np.random.default_rng(3)
    centres = rng.uniform(20, 100, (300, 2))
    sizes = rng.uniform(10, 40, (300, 2))
    boxes = np.concatenate([centres - sizes / 2, centres + sizes / 2], -1).astype(np.float32)
    scores = (rng.uniform(size=(300, 1)) * rng.uniform(size=(300, 3)) ** 3).astype(np.float32)
    (dets,) = detections(boxes[None], scores[None], ["a", "b", "c"], max_detections=10_000)
    expected = darknet_nms(boxes, scores, EVAL_SCORE, NMS_IOU)
    assert len(dets) == len(expected) > 20
    got = set()
    for xyxy, name, score in zip(dets.xyxy, dets.names, dets.scores):
        c = "abc".index(name)
        n = int(np.flatnonzero(np.all(boxes == xyxy, axis=1) & (scores[:, c] == score))[0])
        got.add((n, c))
    assert got == expected
    assert np.all(np.diff(dets.scores) <= 0)  # highest first
    (top,) = detections(boxes[None], scores[None], ["a", "b", "c"], max_detections=7)
    np.testing.assert_array_equal(top.scores, dets.scores[:7])


def test_threshold_overlap_and_classes_by_hand():
    """Two boxes of IoU 0.5 (> 0.45): one survives per class; a third box's class-2 score equals the
    threshold (strict: dropped); one anchor may be detected as two classes."""
    boxes = np.array([[0, 0, 30, 20], [10, 0, 40, 20], [60, 60, 80, 90]], np.float32)  # IoU(0, 1) = 0.5
    scores = np.array([[0.9, 0.0, 0.3], [0.8, 0.7, 0.0], [0.0, 0.0, EVAL_SCORE]], np.float32)
    (dets,) = detections(boxes[None], scores[None], ["car", "bus", "person"])
    assert isinstance(dets, Boxes2D)
    assert dets.names.tolist() == ["car", "bus", "person"]
    np.testing.assert_allclose(dets.scores, [0.9, 0.7, 0.3])
    np.testing.assert_array_equal(dets.xyxy, boxes[[0, 1, 0]])
    (loose,) = detections(boxes[None], scores[None], ["car", "bus", "person"], iou_threshold=0.5)
    assert loose.names.tolist() == ["car", "car", "bus", "person"]  # IoU 0.5 is not > 0.5
    (none,) = detections(np.zeros((1, 0, 4)), np.zeros((1, 0, 3)), ["car", "bus", "person"])
    assert len(none) == 0 and none.scores.shape == (0,)
    with pytest.raises(ValueError, match="class names"):
        detections(boxes[None], scores[None], ["car"])


def test_back_to_the_original_image():
    # plain resize: a 500 x 375 (w x h) image fed at 416 x 416
    scale, offset = resize_transform((416, 416), (375, 500))
    np.testing.assert_allclose(rescale([[41.6, 41.6, 416, 208]], scale, offset, (375, 500)),
                               [[50, 37.5, 500, 187.5]], rtol=1e-6)
    # darknet's letterbox: 500 x 375 -> 416 x 312, centred 52 px down
    scale, offset = letterbox_transform((416, 416), (375, 500))
    np.testing.assert_allclose(offset, [0, 52])
    np.testing.assert_allclose(rescale([[0, 52, 416, 364]], scale, offset, (375, 500)), [[0, 0, 500, 375]], rtol=1e-6)
    np.testing.assert_allclose(letterbox_transform((416, 416), (500, 375))[1], [52, 0])
    # boxes reaching outside are clipped to the image
    np.testing.assert_allclose(rescale([[-20, 30, 450, 500]], *resize_transform((416, 416), (416, 416)), (416, 416)),
                               [[0, 30, 416, 416]])
    boxes = np.array([[[41.6, 41.6, 416, 208], [0, 0, 20, 20]]] * 2, np.float32)
    scores = np.array([[[0.9], [0.0]]] * 2, np.float32)
    dets = detections(boxes, scores, ["car"], image_sizes=[(375, 500), (832, 416)], input_hw=(416, 416))
    np.testing.assert_allclose(dets[0].xyxy, [[50, 37.5, 500, 187.5]], rtol=1e-6)
    np.testing.assert_allclose(dets[1].xyxy, [[41.6, 83.2, 416, 416]], rtol=1e-6)
    boxed = detections(boxes, scores, ["car"], image_sizes=[(375, 500)] * 2, input_hw=(416, 416), letterbox=True)
    np.testing.assert_allclose(boxed[0].xyxy, [[50, 0, 500, 187.5]], rtol=1e-6)
    with pytest.raises(ValueError, match="input_hw"):
        detections(boxes, scores, ["car"], image_sizes=[(375, 500)] * 2)


def test_decoded_outputs_give_boxes2d_per_image():
    """End to end on random outputs: one Boxes2D per image, at most max_detections, inside the image."""
    rng = np.random.default_rng(4)
    outputs = [jnp.asarray(rng.normal(size=(2, 64 // t, 64 // t, 3, 7)) - [0, 0, 0, 0, 3, 0, 0], jnp.float32)
               for t in STRIDES]
    dets = detections(*decode_jit(outputs), ["a", "b"], image_sizes=[(48, 80), (64, 64)], input_hw=(64, 64),
                      max_detections=25)
    assert len(dets) == 2 and all(0 < len(d) <= 25 for d in dets)
    assert dets[0].xyxy[:, [0, 2]].max() <= 80 and dets[0].xyxy[:, [1, 3]].max() <= 48
    assert set(dets[1].names) <= {"a", "b"} and dets[1].scores.min() > EVAL_SCORE

"""YOLOv3 anchors, targets and loss (models/camera): hand-placed boxes, darknet's truth loop and
its loss transcribed cell by cell in numpy, outputs that encode the targets exactly, the ignore
rule, gradients and one compile per input size."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.models.camera.anchors import YOLOV3_ANCHORS, Anchors
from dsfec_jax.models.camera.loss import Yolo3LossConfig, yolo3_loss
from dsfec_jax.models.camera.targets import best_anchors, build_targets, pad_batch, pad_ground_truth

build_jit = jax.jit(build_targets, static_argnames=("input_hw", "num_classes", "anchors", "min_side"))
grad_jit = jax.jit(jax.value_and_grad(yolo3_loss, has_aux=True), static_argnames="cfg")
STRIDES = (8, 16, 32)
# Most tests share one batch shape, so the loss compiles once for them (each compile costs seconds).
HW, BATCH, MAX_BOXES, CLASSES = (64, 96), 2, 10, 3


def loss_jit(*args, **kwargs):
    """(total, parts) from the one compiled value-and-grad."""
    return grad_jit(*args, **kwargs)[0]


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def softplus(x):
    return np.logaddexp(0.0, x)


def padded(boxes, labels, max_boxes=MAX_BOXES, batch=BATCH):
    """Ground truth for `batch` identical images, padded to max_boxes."""
    b, l, m, _ = pad_ground_truth(np.asarray(boxes, np.float32).reshape(-1, 4), labels, max_boxes)
    return np.stack([b] * batch), np.stack([l] * batch), np.stack([m] * batch)


def random_outputs(rng, batch=BATCH, hw=HW, classes=CLASSES, scale=1.0):
    return [jnp.asarray(scale * rng.normal(size=(batch, hw[0] // s, hw[1] // s, 3, 5 + classes)), jnp.float32)
            for s in STRIDES]


def random_truth(rng, batch=BATCH, hw=HW, classes=CLASSES, max_boxes=MAX_BOXES):
    """Random boxes inside the image (sizes from 1 px to the whole input), some padding, one thin
    box and one out-of-range class, and a forced collision (box 1 = box 0 shifted by < 1 px)."""
    h, w = hw
    size = np.exp(rng.uniform(np.log(2), np.log(min(h, w)), (batch, max_boxes, 2)))
    x1 = rng.uniform(0, w - size[..., 0])
    y1 = rng.uniform(0, h - size[..., 1])
    boxes = np.stack([x1, y1, x1 + size[..., 0], y1 + size[..., 1]], -1).astype(np.float32)
    boxes[:, 1] = boxes[:, 0] + rng.uniform(0, 0.4, (batch, 1))
    boxes[:, 2, 2] = boxes[:, 2, 0] + 0.01  # thinner than 0.001 x the input: not real
    labels = rng.integers(0, classes, (batch, max_boxes)).astype(np.int32)
    labels[:, 3] = classes  # out of range: not real
    mask = rng.uniform(size=(batch, max_boxes)) < 0.8
    mask[:, :2] = True
    return boxes, labels, mask


# ------------------------------------------------------------------------------------- references


def reference_targets(gt_boxes, gt_labels, gt_mask, input_hw, classes, anchors=YOLOV3_ANCHORS):
    """darknet's truth loop (forward_yolo_layer), one box at a time in float64: per scale
    positive, coords, coord scale, classes (union on collisions) and the winning box index."""
    h_in, w_in = input_hw
    sizes = np.asarray(anchors.sizes, np.float64)
    batch = gt_boxes.shape[0]
    out = []
    for s, stride in enumerate(anchors.strides):
        grid = (batch, h_in // stride, w_in // stride, 3)
        out.append({"positive": np.zeros(grid, bool), "coords": np.zeros(grid + (4,)), "scale": np.zeros(grid),
                    "classes": np.zeros(grid + (classes,)), "index": -np.ones(grid, int)})
    for b in range(batch):
        for t in range(gt_boxes.shape[1]):
            x1, y1, x2, y2 = (float(v) for v in gt_boxes[b, t])
            bw, bh = x2 - x1, y2 - y1
            if not gt_mask[b, t] or not 0 <= gt_labels[b, t] < classes or bw < 0.001 * w_in or bh < 0.001 * h_in:
                continue
            best_n, best_iou = 0, 0.0
            for n, (aw, ah) in enumerate(sizes):
                inter = min(bw, aw) * min(bh, ah)
                iou = inter / (bw * bh + aw * ah - inter)
                if iou > best_iou:
                    best_n, best_iou = n, iou
            for s, stride in enumerate(anchors.strides):
                if best_n not in anchors.masks[s]:
                    continue
                k = anchors.masks[s].index(best_n)
                cx, cy = (x1 + x2) / 2 / stride, (y1 + y2) / 2 / stride
                i = min(int(cx), w_in // stride - 1)
                j = min(int(cy), h_in // stride - 1)
                o = out[s]
                o["positive"][b, j, i, k] = True
                o["coords"][b, j, i, k] = [cx - i, cy - j, math.log(bw / sizes[best_n, 0]), math.log(bh / sizes[best_n, 1])]
                o["scale"][b, j, i, k] = 2 - bw * bh / (w_in * h_in)
                o["classes"][b, j, i, k, gt_labels[b, t]] = 1.0
                o["index"][b, j, i, k] = t
    return out


def iou_one(a, b):
    inter = max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def reference_loss(outputs, gt_boxes, gt_labels, gt_mask, input_hw, ignore_thresh=0.5, anchors=YOLOV3_ANCHORS):
    """The loss cell by cell (float64): darknet's objectness / ignore / positive rules, squared box
    errors scaled by 2 - wh, BCE objectness and classes, summed and divided by the batch size."""
    classes = outputs[0].shape[-1] - 5
    targets = reference_targets(gt_boxes, gt_labels, gt_mask, input_hw, classes, anchors)
    real = [[t for t in range(gt_boxes.shape[1]) if targets_real(gt_boxes[b, t], gt_labels[b, t], gt_mask[b, t],
                                                                  input_hw, classes)] for b in range(gt_boxes.shape[0])]
    parts = dict(xy=0.0, wh=0.0, obj=0.0, cls=0.0)
    for s, raw in enumerate(outputs):
        raw, stride, o = np.asarray(raw, np.float64), anchors.strides[s], targets[s]
        sizes = anchors.for_scale(s).astype(np.float64)
        for b, j, i, k in np.ndindex(raw.shape[:4]):
            r = raw[b, j, i, k]
            if o["positive"][b, j, i, k]:
                sc, c = o["scale"][b, j, i, k], o["coords"][b, j, i, k]
                parts["xy"] += sc * ((c[0] - sigmoid(r[0])) ** 2 + (c[1] - sigmoid(r[1])) ** 2)
                parts["wh"] += sc * ((c[2] - r[2]) ** 2 + (c[3] - r[3]) ** 2)
                parts["obj"] += softplus(-r[4])
                y = o["classes"][b, j, i, k]
                parts["cls"] += np.sum(y * softplus(-r[5:]) + (1 - y) * softplus(r[5:]))
                continue
            cx, cy = (i + sigmoid(r[0])) * stride, (j + sigmoid(r[1])) * stride
            bw, bh = sizes[k, 0] * np.exp(r[2]), sizes[k, 1] * np.exp(r[3])
            pred = (cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2)
            best = max([iou_one(pred, gt_boxes[b, t]) for t in real[b]], default=0.0)
            if not best > ignore_thresh:
                parts["obj"] += softplus(r[4])
    return {k: v / raw.shape[0] for k, v in parts.items()}


def targets_real(box, label, mask, input_hw, classes):
    w, h = box[2] - box[0], box[3] - box[1]
    return bool(mask) and 0 <= label < classes and w >= 0.001 * input_hw[1] and h >= 0.001 * input_hw[0]


def encode_targets(targets, classes, obj_logit=20.0):
    """Raw outputs that decode to the targets exactly: logit of the cell offsets, the log sizes,
    +obj_logit at positives and -obj_logit elsewhere, class logits +-obj_logit from the targets."""
    outs = []
    for t in targets:
        offset = np.clip(np.asarray(t.coords[..., :2], np.float64), 1e-6, 1 - 1e-6)
        pos = np.asarray(t.positive)
        raw = np.concatenate([np.log(offset / (1 - offset)), np.asarray(t.coords[..., 2:]),
                              np.where(pos, obj_logit, -obj_logit)[..., None],
                              np.where(np.asarray(t.classes) > 0, obj_logit, -obj_logit)], -1)
        outs.append(jnp.asarray(raw, jnp.float32))
    return outs


# ------------------------------------------------------------------------------------------ anchors


def test_anchors_are_darknets_nine_with_their_masks():
    a = YOLOV3_ANCHORS
    assert a.array().shape == (9, 2) and a.strides == (8, 16, 32)
    np.testing.assert_array_equal(a.for_scale(0), [[10, 13], [16, 30], [33, 23]])
    np.testing.assert_array_equal(a.for_scale(1), [[30, 61], [62, 45], [59, 119]])
    np.testing.assert_array_equal(a.for_scale(2), [[116, 90], [156, 198], [373, 326]])
    assert hash(a) == hash(Anchors())  # usable as a static jit argument
    with pytest.raises(ValueError, match="once"):
        Anchors(masks=((0, 1, 2), (3, 4, 5), (6, 7, 7)))
    with pytest.raises(ValueError, match="strides"):
        Anchors(strides=(8, 16))


def test_best_anchor_is_the_shape_iou_maximum():
    wh = np.array([[12, 14], [370, 320], [60, 45], [10, 13], [116, 90], [1000, 1000], [1, 1]], np.float32)
    np.testing.assert_array_equal(np.asarray(best_anchors(wh)), [0, 8, 4, 0, 6, 8, 0])


# ------------------------------------------------------------------------------------------ targets


def test_hand_placed_boxes_go_to_their_anchor_and_centre_cell():
    """12 x 14 at centre (100, 60) -> stride 8, anchor 0, cell (i, j) = (12, 7); 370 x 320 at centre
    (208, 200) -> stride 32, anchor 8 (mask slot 2), cell (6, 6); 60 x 45 at (300, 100) -> stride
    16, anchor 4 (slot 1), cell (18, 6). Both images of the batch hold the same boxes."""
    boxes = [[94, 53, 106, 67], [23, 40, 393, 360], [270, 77.5, 330, 122.5]]
    t8, t16, t32 = build_jit(*padded(boxes, [1, 2, 0]), input_hw=(416, 416), num_classes=CLASSES)
    for t, (j, i, k) in ((t8, (7, 12, 0)), (t16, (6, 18, 1)), (t32, (6, 6, 2))):
        assert np.argwhere(np.asarray(t.positive)).tolist() == [[0, j, i, k], [1, j, i, k]]
    np.testing.assert_allclose(t8.coords[0, 7, 12, 0], [100 / 8 - 12, 60 / 8 - 7, math.log(12 / 10), math.log(14 / 13)],
                               atol=1e-6)
    np.testing.assert_allclose(t32.coords[1, 6, 6, 2], [208 / 32 - 6, 200 / 32 - 6, math.log(370 / 373),
                                                        math.log(320 / 326)], atol=1e-6)
    np.testing.assert_allclose(t32.coord_scale[0, 6, 6, 2], 2 - 370 * 320 / 416**2, rtol=1e-6)
    np.testing.assert_allclose(t8.coord_scale[0, 7, 12, 0], 2 - 12 * 14 / 416**2, rtol=1e-6)
    np.testing.assert_array_equal(t8.classes[0, 7, 12, 0], [0, 1, 0])
    np.testing.assert_array_equal(t32.classes[0, 6, 6, 2], [0, 0, 1])
    assert int(t16.gt_index[0, 6, 18, 1]) == 2 and int(t16.gt_index[0, 0, 0, 0]) == -1
    assert float(t8.coord_scale.sum()) == pytest.approx(2 * (2 - 12 * 14 / 416**2))  # zero elsewhere


def test_rectangular_input_and_centre_on_the_far_edge():
    """(H, W) = (320, 480): the grids are (40, 60), (20, 30), (10, 15); a centre on the right and
    bottom edges falls in the last cell with offset 1."""
    t8 = build_jit(*padded([[470, 310, 490, 330]], [0]), input_hw=(320, 480), num_classes=CLASSES)[0]
    assert t8.positive.shape == (BATCH, 40, 60, 3)
    assert np.argwhere(np.asarray(t8.positive[0])).tolist() == [[39, 59, 1]]  # 20 x 20 -> anchor 1 (16, 30)
    np.testing.assert_allclose(t8.coords[0, 39, 59, 1, :2], [1.0, 1.0])


def test_collision_later_box_wins_coordinates_classes_are_the_union():
    a, b = [94, 53, 106, 67], [95, 54, 106.5, 66]  # same cell (12, 7) at stride 8, both anchor 0
    t8 = build_jit(*padded([a, b], [2, 0]), input_hw=(416, 416), num_classes=CLASSES)[0]
    assert int(t8.positive[0].sum()) == 1 and int(t8.gt_index[0, 7, 12, 0]) == 1
    np.testing.assert_allclose(t8.coords[0, 7, 12, 0, 2], math.log(11.5 / 10), atol=1e-6)
    np.testing.assert_array_equal(t8.classes[0, 7, 12, 0], [1, 0, 1])


@pytest.mark.parametrize("hw", [HW, (96, 64)])
def test_targets_equal_darknets_truth_loop(hw):
    rng = np.random.default_rng(hw[1])
    gt = random_truth(rng, hw=hw)
    ours = build_jit(*gt, input_hw=hw, num_classes=CLASSES)
    for t, ref in zip(ours, reference_targets(*gt, hw, CLASSES)):
        np.testing.assert_array_equal(np.asarray(t.positive), ref["positive"])
        np.testing.assert_array_equal(np.asarray(t.gt_index), ref["index"])
        np.testing.assert_allclose(np.asarray(t.coords), ref["coords"], atol=2e-5)
        np.testing.assert_allclose(np.asarray(t.coord_scale), ref["scale"], atol=1e-6)
        np.testing.assert_array_equal(np.asarray(t.classes), ref["classes"])
    assert sum(int(t.positive.sum()) for t in ours) > 0


def test_padding_keeps_the_largest_and_reports_the_dropped():
    boxes = np.array([[0, 0, 2, 2], [0, 0, 10, 10], [0, 0, 5, 5], [0, 0, 10, 10]], np.float32)
    b, l, m, dropped = pad_ground_truth(boxes, [0, 1, 2, 3], max_boxes=2)
    assert dropped == 2 and m.tolist() == [True, True] and l.tolist() == [1, 3]
    b, l, m, dropped = pad_ground_truth(boxes[:1], [4], max_boxes=3)
    assert dropped == 0 and m.tolist() == [True, False, False] and b.shape == (3, 4) and l.tolist() == [4, 0, 0]
    gt = [Boxes2D(boxes[:2], np.array(["car", "bus"])), Boxes2D.empty()]
    arrays, dropped = pad_batch(gt, ["bus", "car"], max_boxes=4)
    assert dropped == 0 and arrays["gt_labels"][0, :2].tolist() == [1, 0] and arrays["gt_mask"].sum() == 2
    assert arrays["gt_boxes"].shape == (2, 4, 4) and arrays["gt_boxes"].dtype == np.float32
    with pytest.raises(ValueError, match="unknown class"):
        pad_batch(gt, ["car"])
    hard = [Boxes2D(boxes[:3], np.array(["car", "bus", "car"]), difficult=np.array([False, True, False]))]
    arrays, _ = pad_batch(hard, ["bus", "car"], max_boxes=4)
    assert arrays["gt_mask"].sum() == 2 and arrays["gt_boxes"][0, 1].tolist() == [0, 0, 5, 5]
    arrays, _ = pad_batch(hard, ["bus", "car"], max_boxes=4, skip_difficult=False)
    assert arrays["gt_mask"].sum() == 3


# --------------------------------------------------------------------------------------------- loss


def near_truth_outputs(rng, gt, noise=0.3):
    """Random outputs, except that every anchor of a cell holding an assigned box predicts that box
    with noise: some of them are then ignored (IoU > 0.5), others not."""
    outputs = [np.array(o) for o in random_outputs(rng, scale=1.5)]
    for s, t in enumerate(build_jit(*gt, input_hw=HW, num_classes=CLASSES)):
        sizes = YOLOV3_ANCHORS.for_scale(s)
        for b, j, i, k in np.argwhere(np.asarray(t.positive)):
            offset = np.clip(np.asarray(t.coords[b, j, i, k, :2]), 0.01, 0.99)
            for other in range(3):
                outputs[s][b, j, i, other, :2] = np.log(offset / (1 - offset)) + noise * rng.normal(size=2)
                outputs[s][b, j, i, other, 2:4] = (np.asarray(t.coords[b, j, i, k, 2:]) + np.log(sizes[k] / sizes[other])
                                                   + noise * rng.normal(size=2))
    return [jnp.asarray(o) for o in outputs]


def test_loss_equals_the_cell_by_cell_reference():
    rng = np.random.default_rng(7)
    gt = random_truth(rng)
    outputs = near_truth_outputs(rng, gt)
    total, parts = loss_jit(outputs, *gt)
    ref = reference_loss(outputs, *gt, HW)
    for key in ref:
        np.testing.assert_allclose(float(parts[key]), ref[key], rtol=2e-5, err_msg=key)
    np.testing.assert_allclose(float(total), sum(ref.values()), rtol=2e-5)
    assert float(parts["ignored"]) > 0 and float(parts["positives"]) > 0  # every rule took part


def test_outputs_that_encode_the_targets_give_a_near_zero_loss():
    gt = random_truth(np.random.default_rng(3))
    targets = build_jit(*gt, input_hw=HW, num_classes=CLASSES)
    outputs = encode_targets(targets, CLASSES)
    (total, parts), grads = grad_jit(outputs, *gt)
    assert float(parts["positives"]) >= 4
    assert float(parts["xy"]) < 1e-9 and float(parts["wh"]) < 1e-9
    assert float(parts["obj"]) < 1e-4 and float(parts["cls"]) < 1e-5
    assert max(float(jnp.abs(g).max()) for g in grads) < 1e-6  # a minimum: no gradient left

    # moving any part of one assigned prediction away raises the loss
    s, where = next((s, tuple(np.argwhere(np.asarray(t.positive))[0])) for s, t in enumerate(targets)
                    if t.positive.any())
    for channel, delta, part in ((0, 2.0, "xy"), (3, 0.5, "wh"), (4, -25.0, "obj"), (5, 30.0, "cls")):
        moved = list(outputs)
        moved[s] = moved[s].at[where + (channel,)].add(delta)
        _, moved_parts = loss_jit(moved, *gt)
        assert float(moved_parts[part]) > float(parts[part]) + 1e-3, part


def ignore_case(iou, obj_logit=5.0):
    """One GT (16 x 30 centred at (36, 28): anchor 1 (16, 30) of stride 8, cell (4, 3)) in both
    images, and the negative anchor 0 (10, 13) at the same cell with its decoded box centred on the
    GT, the GT's height and iou x its width (so IoU = iou), objectness logit obj_logit."""
    gt = padded([[28, 13, 44, 43]], [0])
    targets = build_jit(*gt, input_hw=HW, num_classes=CLASSES)
    assert np.argwhere(np.asarray(targets[0].positive[0])).tolist() == [[3, 4, 1]]
    outputs = encode_targets(targets, CLASSES)
    raw = np.array(outputs[0])
    raw[:, 3, 4, 0, :2] = 0.0  # centre (4.5, 3.5) cells = (36, 28) pixels
    raw[:, 3, 4, 0, 2:4] = np.log([iou * 16 / 10, 30 / 13])
    raw[:, 3, 4, 0, 4] = obj_logit
    outputs[0] = jnp.asarray(raw)
    return outputs, *gt


def test_ignore_rule_at_iou_0_6_but_not_0_3():
    """A negative anchor with objectness logit 5 costs softplus(5) at IoU 0.3 with the GT and nothing
    at IoU 0.6 (> ignore_thresh 0.5); with ignore_thresh 0.7 it costs again; padded boxes never
    cause an ignore."""
    _, base = loss_jit(*ignore_case(0.3, obj_logit=-20.0))  # the same anchor costs ~2e-9
    _, low = loss_jit(*ignore_case(0.3))
    _, high = loss_jit(*ignore_case(0.6))
    np.testing.assert_allclose(float(low["obj"]) - float(base["obj"]), math.log1p(math.exp(5.0)), rtol=1e-5)
    np.testing.assert_allclose(float(high["obj"]), float(base["obj"]), atol=1e-6)
    assert float(high["ignored"]) == float(low["ignored"]) + BATCH
    _, strict = loss_jit(*ignore_case(0.6), cfg=Yolo3LossConfig(ignore_thresh=0.7))
    np.testing.assert_allclose(float(strict["obj"]) - float(base["obj"]), math.log1p(math.exp(5.0)), rtol=1e-5)
    outputs, boxes, labels, mask = ignore_case(0.6)
    _, padded_only = loss_jit(outputs, boxes, labels, np.zeros_like(mask))
    assert float(padded_only["ignored"]) == 0 and float(padded_only["positives"]) == 0


def test_loss_is_per_image_and_gains_scale_their_parts():
    """loss([x, y]) = (loss([x, x]) + loss([y, y])) / 2: each part is a per-image mean."""
    rng = np.random.default_rng(11)
    gt, outputs = random_truth(rng), random_outputs(rng)
    total, parts = loss_jit(outputs, *gt)
    same = [loss_jit([o[np.array([k, k])] for o in outputs], *(g[[k, k]] for g in gt)) for k in range(2)]
    np.testing.assert_allclose(float(total), (float(same[0][0]) + float(same[1][0])) / 2, rtol=1e-5)
    assert float(parts["positives"]) == (float(same[0][1]["positives"]) + float(same[1][1]["positives"])) / 2
    cfg = Yolo3LossConfig(coord_gain=2.0, obj_gain=0.5, cls_gain=3.0)
    total3, parts3 = loss_jit(outputs, *gt, cfg=cfg)
    for key, gain in (("xy", 2.0), ("wh", 2.0), ("obj", 0.5), ("cls", 3.0)):
        np.testing.assert_allclose(float(parts3[key]), gain * float(parts[key]), rtol=1e-5)
    np.testing.assert_allclose(float(total3), sum(float(parts3[k]) for k in ("xy", "wh", "obj", "cls")), rtol=1e-6)


def test_gradients_are_finite_also_without_any_box():
    rng = np.random.default_rng(5)
    outputs = random_outputs(rng, scale=4.0)
    for gt in (random_truth(rng), tuple(np.zeros_like(g) for g in random_truth(rng))):
        (total, parts), grads = grad_jit(outputs, *gt)
        assert np.isfinite(float(total)) and all(bool(jnp.isfinite(g).all()) for g in grads)
        assert any(float(jnp.abs(g).max()) > 0 for g in grads)
    assert float(parts["positives"]) == 0 and float(parts["xy"]) == 0 and float(parts["cls"]) == 0


def test_one_trace_per_input_size():
    traces = []

    def counted(outputs, boxes, labels, mask):
        traces.append(outputs[0].shape)
        return yolo3_loss(outputs, boxes, labels, mask)[0]

    step = jax.jit(jax.grad(counted))
    rng = np.random.default_rng(2)
    for hw in ((32, 32), (32, 32), (64, 32), (32, 32), (64, 32)):
        step(random_outputs(rng, hw=hw), *random_truth(rng, hw=hw))
    assert len(traces) == 2


def test_outputs_that_do_not_fit_are_refused():
    outputs = random_outputs(np.random.default_rng(0))
    with pytest.raises(ValueError, match="do not fit"):
        yolo3_loss([outputs[0], outputs[2], outputs[1]], *padded([[0, 0, 8, 8]], [0]))

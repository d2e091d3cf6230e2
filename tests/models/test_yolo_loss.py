"""YOLOv8 task-aligned assigner, detection loss and decode (models/yolo_rd): hand-computed cases, the
tie and multi-GT rules of rd-yolo-camera-facts.md §2, and loop-by-loop numpy references."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.models.yolo_rd.assigner import AssignerConfig, assign, candidates_inside
from dsfec_jax.boxes.nms2d import detect_host
from dsfec_jax.models.yolo_rd.config import YoloRDConfig
from dsfec_jax.models.yolo_rd.decode import decode, detect
from dsfec_jax.models.yolo_rd.loss import YoloLossConfig, detection_loss

# jitted once per shape: eager dispatch of the many small ops costs more than compiling
assign_jit = jax.jit(assign, static_argnames="cfg")
loss_jit = jax.jit(detection_loss, static_argnames="cfg")
loss_and_grad = jax.jit(jax.value_and_grad(detection_loss, has_aux=True), static_argnames="cfg")


# ------------------------------------------------------------------------------- numpy references


def ciou_numpy(b1, b2, eps=1e-7):
    """CIoU of one pair of boxes in float64 from its formula (ultralytics/utils/metrics.py bbox_iou with
    CIoU=True): a scalar twin of tests/boxes/test_dfl_nms2d.py's, so test files stay independent."""
    (x1, y1, x2, y2), (u1, v1, u2, v2) = (float(x) for x in b1), (float(x) for x in b2)
    w1, h1, w2, h2 = x2 - x1, y2 - y1 + eps, u2 - u1, v2 - v1 + eps
    inter = max(0.0, min(x2, u2) - max(x1, u1)) * max(0.0, min(y2, v2) - max(y1, v1))
    iou = inter / (w1 * h1 + w2 * h2 - inter + eps)
    c2 = (max(x2, u2) - min(x1, u1)) ** 2 + (max(y2, v2) - min(y1, v1)) ** 2 + eps
    rho2 = ((u1 + u2 - x1 - x2) ** 2 + (v1 + v2 - y1 - y2) ** 2) / 4
    v = 4 / math.pi**2 * (math.atan(w2 / h2) - math.atan(w1 / h1)) ** 2
    return iou - (rho2 / c2 + v * v / (v - iou + 1 + eps))


def widened_to_stride_val(box, stride_val):
    """ultralytics 8.4.190's select_candidates_in_gts: every side shorter than stride_val becomes
    stride_val about the box centre (stride_val = stride[1] = 16 in v8DetectionLoss); None: as is."""
    if stride_val is None:
        return box
    x1, y1, x2, y2 = (float(v) for v in box)
    w, h = x2 - x1, y2 - y1
    w, h = (stride_val if w < stride_val else w), (stride_val if h < stride_val else h)
    cx, cy = (x1 + x2) / 2, (y1 + y2) / 2
    return cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2


def reference_assign(scores, boxes, anchors, gt_labels, gt_boxes, gt_mask, topk=10, alpha=0.5, beta=6.0, eps=1e-9,
                     stride_val=None):
    """The TAL rules one image, one GT, one anchor at a time (float64)."""
    b, a, c = scores.shape
    m = gt_boxes.shape[1]
    out_scores, out_fg, out_idx = np.zeros((b, a, c)), np.zeros((b, a), bool), np.zeros((b, a), int)
    for i in range(b):
        inside, overlap, align = np.zeros((m, a), bool), np.zeros((m, a)), np.zeros((m, a))
        positive = np.zeros((m, a), bool)
        for g in range(m):
            if not gt_mask[i, g]:
                continue
            x1, y1, x2, y2 = widened_to_stride_val(gt_boxes[i, g], stride_val)
            for j, (x, y) in enumerate(anchors):
                inside[g, j] = min(x - x1, y - y1, x2 - x, y2 - y) > eps
                if inside[g, j]:
                    overlap[g, j] = max(float(ciou_numpy(gt_boxes[i, g], boxes[i, j])), 0.0)
                    align[g, j] = scores[i, j, gt_labels[i, g]] ** alpha * overlap[g, j] ** beta
            for j in np.argsort(-align[g], kind="stable")[:min(topk, a)]:
                positive[g, j] = inside[g, j]
        for j in range(a):
            if positive[:, j].sum() > 1:
                positive[:, j] = np.arange(m) == np.argmax(overlap[:, j])
            out_fg[i, j] = positive[:, j].any()
            out_idx[i, j] = np.argmax(positive[:, j]) if m else 0
        for j in np.flatnonzero(out_fg[i]):
            g = out_idx[i, j]
            best_align = (align[g] * positive[g]).max()
            best_overlap = (overlap[g] * positive[g]).max()
            out_scores[i, j, gt_labels[i, g]] = align[g, j] * best_overlap / (best_align + eps)
    return out_scores, out_fg, out_idx


def reference_loss(outputs, strides, gt_boxes, gt_labels, gt_mask, reg_max=16):
    """v8DetectionLoss the long way (float64): (total, box, cls, dfl), gains applied, times batch."""
    flat = np.concatenate([np.asarray(o, np.float64).reshape(o.shape[0], -1, o.shape[-1]) for o in outputs], 1)
    anchors = np.concatenate([np.stack(np.meshgrid(np.arange(o.shape[2]) + 0.5, np.arange(o.shape[1]) + 0.5),
                                       -1).reshape(-1, 2) for o in outputs])
    stride = np.concatenate([np.full(o.shape[1] * o.shape[2], s, np.float64) for o, s in zip(outputs, strides)])
    logits = flat[..., : 4 * reg_max].reshape(*flat.shape[:2], 4, reg_max)
    probs = np.exp(logits - logits.max(-1, keepdims=True))
    probs /= probs.sum(-1, keepdims=True)
    dist = probs @ np.arange(reg_max)
    pred = np.concatenate([anchors - dist[..., :2], anchors + dist[..., 2:]], -1)  # grid units
    cls_logits = flat[..., 4 * reg_max:]
    target_scores, fg, idx = reference_assign(1 / (1 + np.exp(-cls_logits)), pred * stride[:, None],
                                              anchors * stride[:, None], gt_labels, gt_boxes, gt_mask)
    tss = max(target_scores.sum(), 1.0)
    bce = np.maximum(cls_logits, 0) - cls_logits * target_scores + np.log1p(np.exp(-np.abs(cls_logits)))
    box = dfl = 0.0
    for i, j in zip(*np.nonzero(fg)):
        weight = target_scores[i, j].sum()
        target = gt_boxes[i, idx[i, j]] / stride[j]
        box += (1 - ciou_numpy(pred[i, j], target)) * weight
        t = np.clip(np.r_[anchors[j] - target[:2], target[2:] - anchors[j]], 0, reg_max - 1.01)
        log_p = np.log(probs[i, j])
        left = np.floor(t).astype(int)
        w_left = left + 1 - t
        dfl += np.mean(-log_p[np.arange(4), left] * w_left - log_p[np.arange(4), left + 1] * (1 - w_left)) * weight
    box, cls, dfl = 7.5 * box / tss, 0.5 * bce.sum() / tss, 1.5 * dfl / tss
    return (box + cls + dfl) * len(flat), box, cls, dfl


def random_batch(seed, batch=2, height=64, width=32, nc=3, slots=4):
    """Random head outputs for a height x width input (strides 8, 16, 32) and padded GTs."""
    rng = np.random.default_rng(seed)
    outputs = [jnp.asarray(rng.normal(0, 1.5, (batch, height // s, width // s, 64 + nc)), jnp.float32)
               for s in (8, 16, 32)]
    xy = rng.uniform(0, [width - 6, height - 6], (batch, slots, 2))
    gt_boxes = np.concatenate([xy, xy + rng.uniform(5, [width / 2, height / 2], (batch, slots, 2))], -1)
    gt_labels = rng.integers(0, nc, (batch, slots))
    gt_mask = np.arange(slots)[None] < rng.integers(1, slots + 1, (batch, 1))
    return outputs, gt_boxes.astype(np.float32), gt_labels, gt_mask


def square(cx, cy, side):
    return [cx - side / 2, cy - side / 2, cx + side / 2, cy + side / 2]


# ------------------------------------------------------------------------------------- assigner


def test_candidates_are_anchor_centres_strictly_inside_the_gt():
    anchors = jnp.array([[4.0, 4.0], [0.0, 4.0], [8.0, 4.0], [4.0, 8.0], [0.5, 7.5], [9.0, 4.0]])
    inside = candidates_inside(anchors, jnp.array([[[0.0, 0.0, 8.0, 8.0]]]))
    assert inside[0, 0].tolist() == [True, False, False, False, True, False]  # on an edge is outside


def test_small_boxes_have_no_candidate_unless_widened():
    anchors = jnp.array([[4.0, 4.0], [12.0, 4.0], [4.0, 12.0]])  # stride-8 cell centres
    thin = jnp.array([[[6.0, 1.0, 10.0, 7.0]]])  # 4 x 6 pixels between two centres
    assert not candidates_inside(anchors, thin).any()
    widened = candidates_inside(anchors, thin, small_side=(8.0, 16.0))  # both sides -> 16 about (8, 4)
    assert widened[0, 0].tolist() == [True, True, False]


def test_topk_picks_the_best_aligned_candidates_and_normalises_their_scores():
    anchors = jnp.array([[2.0, 2.0], [6.0, 2.0], [2.0, 6.0], [10.0, 10.0]])  # the last is outside the GT
    pred = jnp.array([[square(4, 4, 8), square(4, 4, 4), square(4, 4, 6), square(4, 4, 8)]])  # IoU 1, 1/4, 9/16, 1
    scores = jnp.array([[[0.3, 0.25], [0.3, 0.81], [0.3, 0.5], [0.3, 0.9]]])
    got = assign_jit(scores, pred, anchors, jnp.array([[1]]), jnp.array([[[0.0, 0, 8, 8]]]), jnp.array([[True]]),
                 cfg=AssignerConfig(topk=2))
    align = [0.25**0.5 * 1.0, 0.81**0.5 * 0.25**6, 0.5**0.5 * (9 / 16) ** 6]  # anchor 1 is third: not taken
    assert got.foreground.tolist() == [[True, False, True, False]]
    np.testing.assert_allclose(got.scores[0, :, 1], [1.0, 0.0, align[2] * 1.0 / align[0], 0.0], rtol=1e-5)
    np.testing.assert_array_equal(got.scores[0, :, 0], 0.0)
    assert got.labels.tolist() == [[1, 1, 1, 1]] and got.gt_index.tolist() == [[0, 0, 0, 0]]
    np.testing.assert_array_equal(got.boxes[0], [[0, 0, 8, 8]] * 4)


def test_an_anchor_claimed_by_several_gts_takes_the_one_of_highest_overlap():
    gts = jnp.array([[[0.0, 0, 8, 12], [0.0, 0, 8, 8]]])  # the anchor's prediction is GT 1 exactly
    got = assign_jit(jnp.full((1, 1, 2), 0.5), jnp.array([[[0.0, 0, 8, 8]]]), jnp.array([[2.0, 2.0]]),
                 jnp.array([[0, 1]]), gts, jnp.array([[True, True]]))
    assert got.foreground.tolist() == [[True]] and got.gt_index.tolist() == [[1]] and got.labels.tolist() == [[1]]
    np.testing.assert_allclose(got.scores[0, 0], [0.0, 1.0], atol=1e-5)


def test_equal_overlaps_go_to_the_first_gt():
    gts = jnp.array([[[0.0, 0, 8, 8], [0.0, 0, 8, 8]]])  # the same box twice, labels 1 and 0
    got = assign_jit(jnp.full((1, 2, 2), 0.5), jnp.array([[[0.0, 0, 8, 8], [2.0, 2, 6, 6]]]),
                 jnp.array([[2.0, 2.0], [6.0, 6.0]]), jnp.array([[1, 0]]), gts, jnp.array([[True, True]]),
                 cfg=AssignerConfig(topk=1))
    assert got.foreground.tolist() == [[True, False]]
    assert got.gt_index[0, 0] == 0 and got.labels[0, 0] == 1
    np.testing.assert_allclose(got.scores[0, 0], [0.0, 1.0], atol=1e-5)


def test_the_overlap_argmax_runs_over_every_gt_not_only_the_claimants():
    """GTs 0 and 1 both take anchor 0 (topk 1); GT 2 takes anchor 2 but overlaps anchor 0's prediction
    most, so ultralytics' select_highest_overlaps hands anchor 0 to GT 2."""
    anchors = jnp.array([[2.0, 2.0], [12.0, 2.0], [2.0, 12.0]])
    gts = np.array([[[0.0, 0, 8, 8], [0.0, 0, 16, 8], [0.0, 0, 8, 16]]])
    pred = np.array([[[0.0, 0, 8, 12], [10.0, 0, 14, 4], [0.0, 0, 8, 16]]])
    got = assign_jit(jnp.full((1, 3, 3), 0.5), jnp.asarray(pred), anchors, jnp.array([[0, 1, 2]]), jnp.asarray(gts),
                 jnp.array([[True, True, True]]), cfg=AssignerConfig(topk=1))
    overlap_gt2 = ciou_numpy(gts[0, 2], pred[0, 0])
    assert ciou_numpy(gts[0, 1], pred[0, 1]) < ciou_numpy(gts[0, 1], pred[0, 0]) < ciou_numpy(gts[0, 0], pred[0, 0])
    assert ciou_numpy(gts[0, 0], pred[0, 0]) < overlap_gt2 < 1.0
    assert got.foreground.tolist() == [[True, False, True]] and got.gt_index.tolist() == [[2, 0, 2]]
    np.testing.assert_allclose(got.scores[0, :, 2], [overlap_gt2**6, 0.0, 1.0], rtol=1e-4)
    np.testing.assert_array_equal(got.scores[0, :, :2], 0.0)


def test_padded_gts_change_nothing_and_no_gts_means_background():
    outputs, gt_boxes, gt_labels, gt_mask = random_batch(0)
    scores = jax.nn.sigmoid(jnp.asarray(np.random.default_rng(1).normal(size=(2, 42, 3)), jnp.float32))
    pred = jnp.asarray(np.tile(square(16, 32, 20), (2, 42, 1)), jnp.float32)
    anchors = jnp.asarray(np.random.default_rng(2).uniform(0, 32, (42, 2)), jnp.float32)
    padded = (np.concatenate([gt_labels, [[1], [2]]], 1),
              np.concatenate([gt_boxes, np.tile([[[0.0, 0, 64, 64]]], (2, 1, 1))], 1),
              np.concatenate([gt_mask, [[False], [False]]], 1))
    plain = assign_jit(scores, pred, anchors, gt_labels, gt_boxes, gt_mask)
    with_pad = assign_jit(scores, pred, anchors, *padded)
    for name in ("scores", "foreground", "gt_index", "labels", "boxes"):
        np.testing.assert_array_equal(getattr(plain, name), getattr(with_pad, name))
    assert plain.foreground.any()
    no_slot = (np.zeros((2, 0), int), np.zeros((2, 0, 4)), np.zeros((2, 0), bool))
    for empty in (assign_jit(scores, pred, anchors, gt_labels, gt_boxes, np.zeros_like(gt_mask)),
                  assign_jit(scores, pred, anchors, *no_slot)):
        assert not empty.foreground.any() and not empty.scores.any()


def realistic_assigner_batch(seed, batch=2, height=96, width=64, nc=3, slots=8):
    """What the assigner sees in training, small: the anchors of strides 8, 16 and 32 on a height x
    width input (126), up to `slots` GTs an image with sides of 4-40 px (many of 8-16 px), predicted
    boxes scattered about their anchors and random class scores."""
    rng = np.random.default_rng(seed)
    anchors = np.concatenate([np.stack(np.meshgrid(np.arange(width // s) * s + s / 2, np.arange(height // s) * s + s / 2),
                                       -1).reshape(-1, 2) for s in (8, 16, 32)])
    strides = np.concatenate([np.full((height // s) * (width // s), s) for s in (8, 16, 32)])
    size = rng.uniform(4, 40, (batch, slots, 2))
    corner = rng.uniform(0, [width, height], (batch, slots, 2)) - size / 2
    gt_boxes = np.clip(np.concatenate([corner, corner + size], -1), 0, [width, height, width, height])
    gt_labels = rng.integers(0, nc, (batch, slots))
    gt_mask = np.arange(slots)[None] < rng.integers(3, slots + 1, (batch, 1))
    centre = anchors[None] + rng.normal(0, strides[None, :, None] / 2, (batch, len(anchors), 2))
    half = rng.uniform(2, 20, (batch, len(anchors), 2))
    pred = np.concatenate([centre - half, centre + half], -1)
    scores = rng.uniform(0.01, 1, (batch, len(anchors), nc))
    return [x.astype(np.float32) for x in (scores, pred, anchors, gt_boxes)] + [gt_labels, gt_mask]


# the family's own setting (models/yolo_rd/family.py): what training runs
FAMILY_ASSIGNER = AssignerConfig(small_side=YoloRDConfig().assign_small_side)


def test_the_realistic_fixture_has_sides_that_the_two_small_box_rules_treat_differently():
    """So the reference test below tells ultralytics 8.4.190's rule (sides under 16 px -> 16) from
    the one the shipped weights used (only sides under 8 px -> 16)."""
    changed = 0
    for seed in range(6):
        _, _, anchors, gt_boxes, _, gt_mask = realistic_assigner_batch(seed)
        rules = [np.asarray(candidates_inside(anchors, gt_boxes, small_side=r)) & gt_mask[..., None]
                 for r in ((16.0, 16.0), (8.0, 16.0))]
        changed += int((rules[0] != rules[1]).sum())
    assert changed > 20


@pytest.mark.parametrize("seed", range(6))
def test_assigner_matches_ultralytics_8_4_190_loop_by_loop(seed):
    """The family's assigner against a numpy transcription of 8.4.190's TaskAlignedAssigner as
    v8DetectionLoss builds it (topk 10, stride_val 16), on realistic batches: several GTs compete,
    and the best overlap that normalises the target scores must be taken over each GT's positives."""
    scores, pred, anchors, gt_boxes, gt_labels, gt_mask = realistic_assigner_batch(seed)
    got = assign_jit(scores, pred, anchors, gt_labels, gt_boxes, gt_mask, cfg=FAMILY_ASSIGNER)
    want_scores, want_fg, want_idx = reference_assign(scores, pred, anchors, gt_labels, gt_boxes, gt_mask,
                                                      topk=10, stride_val=16.0)
    assert want_fg.sum() > 20
    np.testing.assert_array_equal(got.foreground, want_fg)
    np.testing.assert_array_equal(np.where(want_fg, got.gt_index, 0), np.where(want_fg, want_idx, 0))
    np.testing.assert_allclose(got.scores, want_scores, rtol=1e-4, atol=1e-6)


def test_the_bare_assigner_keeps_the_yolov8_era_rule():
    scores, pred, anchors, gt_boxes, gt_labels, gt_mask = realistic_assigner_batch(0)
    got = assign_jit(scores, pred, anchors, gt_labels, gt_boxes, gt_mask)
    want_scores, want_fg, _ = reference_assign(scores, pred, anchors, gt_labels, gt_boxes, gt_mask, topk=10)
    np.testing.assert_array_equal(got.foreground, want_fg)
    np.testing.assert_allclose(got.scores, want_scores, rtol=1e-4, atol=1e-6)


# ----------------------------------------------------------------------------------------- loss


def test_with_no_gt_only_the_classification_term_remains():
    outputs, gt_boxes, gt_labels, _ = random_batch(3)
    no_gt = np.zeros((2, 4), bool)
    (total, parts), grads = loss_and_grad(outputs, gt_boxes, gt_labels, no_gt)
    class_logits = np.concatenate([np.asarray(o).reshape(2, -1, 67)[..., 64:] for o in outputs], 1)
    softplus = np.logaddexp(0.0, class_logits).sum()  # BCE against 0, target_scores_sum clamped to 1
    np.testing.assert_allclose(parts["cls"], 0.5 * softplus, rtol=1e-5)
    assert parts["box"] == 0 and parts["dfl"] == 0 and parts["foreground"] == 0
    np.testing.assert_allclose(total, 2 * 0.5 * softplus, rtol=1e-5)
    assert all(np.isfinite(np.asarray(g)).all() for g in grads)
    total_empty, _ = loss_jit(outputs, np.zeros((2, 0, 4)), np.zeros((2, 0), int), np.zeros((2, 0), bool))
    np.testing.assert_allclose(total_empty, total, rtol=1e-6)


@pytest.mark.parametrize("seed", range(2))
def test_loss_matches_a_loop_by_loop_reference(seed):
    outputs, gt_boxes, gt_labels, gt_mask = random_batch(10 + seed)
    (total, parts), _ = loss_and_grad(outputs, gt_boxes, gt_labels, gt_mask)
    want_total, box, cls, dfl = reference_loss(outputs, (8, 16, 32), gt_boxes, gt_labels, gt_mask)
    assert parts["foreground"] > 0 and box > 0 and dfl > 0
    np.testing.assert_allclose([parts["box"], parts["cls"], parts["dfl"]], [box, cls, dfl], rtol=2e-4)
    np.testing.assert_allclose(total, want_total, rtol=2e-4)
    unscaled, _ = loss_jit(outputs, gt_boxes, gt_labels, gt_mask, cfg=YoloLossConfig(scale_by_batch=False))
    np.testing.assert_allclose(unscaled * 2, total, rtol=1e-6)


def test_loss_and_gradients_are_finite_jitted_and_a_few_steps_lower_the_loss():
    outputs, gt_boxes, gt_labels, gt_mask = random_batch(20)
    outputs_0 = outputs
    losses = []
    for _ in range(5):
        (loss, _), grads = loss_and_grad(outputs, gt_boxes, gt_labels, gt_mask)
        assert all(np.isfinite(np.asarray(g)).all() for g in grads)
        losses.append(float(loss))
        outputs = [o - 0.3 * g for o, g in zip(outputs, grads)]
    np.testing.assert_allclose(losses[0], loss_jit(outputs_0, gt_boxes, gt_labels, gt_mask)[0], rtol=1e-5)
    assert losses[-1] < 0.8 * losses[0], losses


# --------------------------------------------------------------------------------------- decode


def test_decode_turns_peaked_bins_into_pixel_boxes_and_logits_into_probabilities():
    level = np.zeros((1, 1, 2, 64 + 2), np.float32)  # stride 8, one row, two cells
    for side, bin_ in enumerate((2, 3, 1, 4)):  # left, top, right, bottom in grid units
        level[0, 0, :, side * 16 + bin_] = 40.0
    level[0, 0, :, 64:] = [[0.0, 2.0], [-1.0, 0.0]]
    boxes, scores = decode([jnp.asarray(level)], strides=(8,))
    np.testing.assert_allclose(boxes[0], [[(0.5 - 2) * 8, (0.5 - 3) * 8, (0.5 + 1) * 8, (0.5 + 4) * 8],
                                          [(1.5 - 2) * 8, (0.5 - 3) * 8, (1.5 + 1) * 8, (0.5 + 4) * 8]], atol=1e-4)
    np.testing.assert_allclose(scores[0], 1 / (1 + np.exp(-np.array([[0.0, 2.0], [-1.0, 0.0]]))), rtol=1e-6)


def test_compiled_detect_equals_decode_then_host_nms_per_image():
    outputs = random_batch(30)[0]
    boxes, scores = decode(outputs)
    got_boxes, got_scores, got_labels, valid = jax.jit(detect, static_argnames="max_detections")(
        outputs, 0.1, 0.3, max_detections=20)
    for i in range(2):
        want = detect_host(np.asarray(boxes[i]), np.asarray(scores[i]), 0.1, 0.3, 20)
        assert 0 < valid[i].sum() == len(want[0])
        np.testing.assert_allclose(got_boxes[i][valid[i]], want[0], rtol=1e-6)
        np.testing.assert_array_equal(got_labels[i][valid[i]], want[2])

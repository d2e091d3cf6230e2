"""Rotated NMS against a plainly written greedy reference, on many random scenes and on the
candidate boxes the shipped DSFEC-S predictor emits on synthetic frames: the same indices, in order."""

import numpy as np
import pytest

from dsfec_jax.boxes.nms import batched_rotated_nms, rotated_nms
from dsfec_jax.boxes.nms_kernel import aligned_ious
from dsfec_jax.boxes.rotated_iou import bev_iou, bev_iou_aligned, circumradius

PI = np.pi


def reference_nms(boxes, scores, labels, threshold, max_output=None, score_threshold=None, pre_top_k=None):
    """Greedy NMS written out: per label, best score first (ties: lower index); keep a box unless a
    kept box of its label overlaps it with IoU > threshold. IoU of (kept box, box), from one matrix."""
    iou = bev_iou(boxes, boxes)
    keep = []
    for label in np.unique(labels):
        candidates = [i for i in range(len(scores)) if labels[i] == label and not np.isnan(scores[i])
                      and (score_threshold is None or scores[i] > score_threshold)]
        candidates.sort(key=lambda i: (-scores[i], i))
        kept = []
        for i in candidates[:pre_top_k]:
            if all(iou[k, i] <= threshold for k in kept):
                kept.append(i)
        keep += kept
    keep.sort(key=lambda i: (-scores[i], i))
    return keep[:max_output]


def _scene(rng, n):
    """Jittered clusters (so boxes suppress each other), lattice boxes with shared edges and exact
    IoU ties, exact duplicates and flipped copies, degenerate boxes; tied and NaN scores."""
    kinds = rng.integers(0, 3, n)
    centres = np.c_[rng.uniform(-8, 8, (6, 2)), rng.uniform(0.5, 3, (6, 2)), rng.uniform(-PI, PI, 6)]
    jitter = np.c_[rng.normal(0, 0.4, (n, 2)), rng.normal(0, 0.2, (n, 2)), rng.normal(0, 0.2, n)]
    boxes = centres[rng.integers(0, 6, n)] + jitter
    boxes[kinds == 1] = np.c_[rng.integers(-4, 5, (n, 2)) / 2, rng.integers(1, 6, (n, 2)) / 2,
                              rng.integers(-2, 3, n) * PI / 2][kinds == 1]
    if n >= 8:
        boxes[-3:] = boxes[:3]                       # duplicates
        boxes[-4] = boxes[3] + [0, 0, 0, 0, PI]      # the same rectangle, heading reversed
        boxes[-5, 2] = 0.0                           # degenerate
        boxes[-6, 3] = -1.0
    scores = np.round(rng.uniform(0, 1, n), 1)
    scores[rng.uniform(size=n) < 0.05] = np.nan
    labels = rng.integers(0, rng.integers(1, 4), n)
    return boxes, scores, labels


@pytest.mark.parametrize("seed", range(60))
def test_matches_the_reference_greedy_on_random_scenes(seed):
    rng = np.random.default_rng(seed)
    boxes, scores, labels = _scene(rng, int(rng.integers(0, 70)))
    n = len(boxes)
    for threshold in (0.0, 0.2, 1 / 3, 0.5, float(rng.uniform()), 1.0):
        options = {"max_output": None if rng.uniform() < 0.5 else int(rng.integers(0, n + 2)),
                   "score_threshold": None if rng.uniform() < 0.5 else float(rng.uniform(0, 0.8)),
                   "pre_top_k": None if rng.uniform() < 0.6 else int(rng.integers(0, n + 2))}
        want = reference_nms(boxes, scores, labels, threshold, **options)
        got = batched_rotated_nms(boxes, scores, labels, threshold, **options)
        assert got.dtype == np.int64
        assert got.tolist() == want, (threshold, options)
        one = rotated_nms(boxes, scores, threshold, **options)
        assert one.tolist() == reference_nms(boxes, scores, np.zeros(n), threshold, **options)


def test_threshold_equal_to_a_computed_iou_keeps_both():
    """'Strictly above' at exact ties: two boxes whose IoU is the threshold itself both stay; one
    float below it, the lower-scored one goes."""
    boxes = np.array([[0.0, 0.0, 2.0, 4.0, 0.3], [0.7, 0.4, 2.2, 3.9, 0.5]])
    iou = bev_iou(boxes[0], boxes[1])[0, 0]
    assert 0 < iou < 1
    scores = np.array([0.9, 0.8])
    assert rotated_nms(boxes, scores, iou).tolist() == [0, 1]
    assert rotated_nms(boxes, scores, np.nextafter(iou, 0.0)).tolist() == [0]


def test_compiled_pair_iou_is_bitwise_the_clipping_iou():
    """The compiled pass's IoU is `bev_iou_aligned`'s to the last bit (so every NMS decision is the
    plain pass's, ties included): random scenes with shared edges, duplicates, flipped and
    degenerate boxes, and far-away or NaN boxes."""
    rng = np.random.default_rng(3)
    boxes, _, _ = _scene(rng, 400)
    boxes[5] = [np.nan, 0, 1, 1, 0]
    boxes[6] = [1e6, -1e6, 2, 4, 0.1]
    i, j = rng.integers(0, len(boxes), (2, 20000))
    a, b = boxes[i], boxes[j]
    args = [(x, np.cos(x[:, 4]), np.sin(x[:, 4]), circumradius(x)) for x in (a, b)]
    got = aligned_ious(*args[0], *args[1])
    want = bev_iou_aligned(a, b)
    assert ((got > 0) & (got < 1)).sum() > 1000  # many partial overlaps were clipped
    np.testing.assert_array_equal(got, want)
    # a perturbation of the arithmetic shows: a corner nudged by one ulp moves some IoUs
    nudged = a.copy()
    nudged[:, 0] = np.nextafter(nudged[:, 0], np.inf)
    assert (aligned_ious(nudged, *args[0][1:], *args[1]) != want).any()


def test_a_long_chain_of_overlapping_boxes():
    """Each box overlaps its neighbours: kept and suppressed alternate along the chain."""
    n = 120
    boxes = np.c_[np.arange(n) * 0.6, np.zeros(n), np.full(n, 2.0), np.full(n, 4.0), np.zeros(n)]
    for scores in (np.linspace(1, 0, n), np.random.default_rng(4).uniform(size=n)):
        for threshold in (0.1, 0.3, 0.6):
            want = reference_nms(boxes, scores, np.zeros(n), threshold)
            assert rotated_nms(boxes, scores, threshold).tolist() == want


def test_labels_of_any_kind_and_bad_input():
    boxes = np.array([[0.0, 0.0, 2.0, 4.0, 0.2]] * 4)
    scores = np.array([0.9, 0.8, 0.7, 0.6])
    assert batched_rotated_nms(boxes, scores, np.array(["car", "ped", "car", "x"]), 0.5).tolist() == [0, 1, 3]
    assert batched_rotated_nms(boxes, np.full(4, np.nan), np.zeros(4), 0.5).tolist() == []
    with pytest.raises(ValueError, match="one score and one label per box"):
        batched_rotated_nms(boxes, scores[:3], np.zeros(4), 0.5)
    with pytest.raises(ValueError, match="max_output"):
        rotated_nms(boxes, scores, 0.5, max_output=-1)
    with pytest.raises(ValueError, match="pre_top_k"):
        rotated_nms(boxes, scores, 0.5, pre_top_k=-2)
    with pytest.raises(ValueError, match="iou_threshold"):
        batched_rotated_nms(np.zeros((0, 5)), np.zeros(0), np.zeros(0), float("nan"))


@pytest.fixture(scope="module")
def dsfec_s_candidates():
    """The decoded top-k candidates (before NMS) of the shipped DSFEC-S on two synthetic test
    frames, with the predictor that made them."""
    from dsfec_jax import api
    from dsfec_jax.data.points.pillarize import pillarize, select_columns
    from dsfec_jax.data.points.sources import load_frames

    predictor = api.load("dsfec_s", max_pillars=512)
    frames = load_frames("synthetic", "test", 2)
    out = []
    for frame in frames:
        tensors = pillarize(select_columns(frame, predictor.spec.features), predictor.spec)[0]
        boxes, scores, labels = predictor.run({k: v[None] for k, v in tensors.items()})
        out.append((frame, boxes[0], scores[0], labels[0]))
    return predictor, out


def test_dsfec_s_detections_equal_the_reference_greedy(dsfec_s_candidates):
    predictor, frames = dsfec_s_candidates
    for frame, boxes, scores, labels in frames:
        options = {"max_output": predictor.max_boxes, "score_threshold": predictor.score_threshold}
        want = reference_nms(boxes.astype(np.float64), scores.astype(np.float64), labels, predictor.nms_iou, **options)
        got = batched_rotated_nms(boxes.astype(np.float64), scores, labels, predictor.nms_iou, **options)
        assert got.tolist() == want
        assert 0 < len(want) < (scores > predictor.score_threshold).sum()  # boxes were suppressed
        detections = predictor(frame)
        np.testing.assert_array_equal(detections.scores, scores[want])
        np.testing.assert_array_equal(detections.boxes.center[:, :2], boxes[want, :2])


def test_nan_labels_and_scores_never_take_part():
    boxes = np.array([[0.0, 0.0, 2.0, 4.0, 0.2], [5.0, 0, 2, 4, 0], [9.0, 0, 2, 4, 0]])
    labels = np.array([0.0, np.nan, 1.0])
    assert batched_rotated_nms(boxes, np.array([0.9, 0.8, np.nan]), labels, 0.5).tolist() == [0]

"""The fast 'IoU above a threshold?' answers equal the exact clipping's, ties and touching boxes included."""

import warnings

import numpy as np
import pytest

from dsfec_jax.boxes import iou_decision
from dsfec_jax.boxes.geometry import bev_corners
from dsfec_jax.boxes.iou_decision import bev_iou_exceeds, box_geometry, pair_iou_exceeds
from dsfec_jax.boxes.rotated_iou import bev_iou, bev_iou_aligned

PI = np.pi


def _random_boxes(rng, n, spread=3.0):
    return np.c_[rng.uniform(-spread, spread, (n, 2)), rng.uniform(0.1, 5.0, (n, 2)), rng.uniform(-PI, PI, n)]


def _snapped_boxes(rng, n):
    """Axis-aligned boxes on a half-metre lattice: shared and collinear edges, exact IoU ties."""
    return np.c_[rng.integers(-4, 5, (n, 2)) / 2, rng.integers(1, 6, (n, 2)) / 2, rng.integers(-2, 3, n) * PI / 2]


def _hard_pairs(rng, n=600):
    """Random, lattice, identical, flipped (same rectangle, heading + pi), concentric and nearly
    identical pairs, and degenerate boxes."""
    a = np.r_[_random_boxes(rng, n), _snapped_boxes(rng, n)]
    b = np.r_[_random_boxes(rng, n), _snapped_boxes(rng, n)]
    b[::7] = a[::7]
    b[1::11] = a[1::11] + [0, 0, 0, 0, PI]
    b[2::13, :2] = a[2::13, :2]
    b[3::17] = a[3::17] + [1e-9, -1e-9, 0, 0, 1e-12]
    b[4::19, 2] = 0.0
    a[5::23, 3] = -1.0
    return a, b


def test_bev_iou_aligned_is_bitwise_the_matrix_diagonal():
    a, b = _hard_pairs(np.random.default_rng(0), 200)
    np.testing.assert_array_equal(bev_iou_aligned(a, b), np.diagonal(bev_iou(a, b)))
    np.testing.assert_array_equal(bev_iou_aligned(a[3], b[3]), bev_iou(a[3], b[3])[0])
    with pytest.raises(ValueError, match="aligned pairs"):
        bev_iou_aligned(a[:3], b[:2])


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("threshold", [0.0, 0.1, 0.2, 0.25, 1 / 3, 0.5, 0.9, 1.0])
def test_answers_equal_the_exact_clipping(seed, threshold):
    a, b = _hard_pairs(np.random.default_rng(seed))
    want = bev_iou_aligned(a, b) > threshold
    assert not want.all() and (want.any() or threshold == 1.0)  # both answers occur
    np.testing.assert_array_equal(bev_iou_exceeds(a, b, threshold), want)


def test_thresholds_at_the_exact_iou_itself_are_answered_exactly():
    """At a threshold equal to a pair's computed IoU (or one float away) only the exact clipping
    can answer: 'strictly above' must then be the clipping's answer, bit for bit."""
    rng = np.random.default_rng(5)
    a, b = _hard_pairs(rng, 150)
    iou = bev_iou_aligned(a, b)
    picked = np.flatnonzero(iou > 0)[:60]
    for p in picked:
        for threshold in (iou[p], np.nextafter(iou[p], 0.0), np.nextafter(iou[p], 1.0)):
            if 0.0 <= threshold <= 1.0:
                assert bev_iou_exceeds(a[p:p + 1], b[p:p + 1], threshold)[0] == (iou[p] > threshold)


def test_pairs_by_index_and_the_touching_shortcut():
    rng = np.random.default_rng(6)
    boxes = _random_boxes(rng, 80, spread=6.0)
    first, second = np.triu_indices(len(boxes), 1)
    g = box_geometry(boxes)
    want = bev_iou(boxes, boxes)[first, second] > 0.2
    np.testing.assert_array_equal(pair_iou_exceeds(g, first, second, 0.2), want)
    touching = np.flatnonzero(bev_iou(boxes, boxes)[first, second] > 0)
    np.testing.assert_array_equal(pair_iou_exceeds(g, first[touching], second[touching], 0.2, touching=True),
                                  want[touching])


def test_generic_pairs_rarely_need_the_exact_clipping(monkeypatch):
    """The point of the module: random overlapping pairs are answered without clipping (a
    regression that sent everything to the fallback would still be correct, and slow)."""
    calls = []
    exact = iou_decision.bev_iou_aligned
    monkeypatch.setattr(iou_decision, "bev_iou_aligned", lambda a, b: calls.append(len(a)) or exact(a, b))
    rng = np.random.default_rng(7)
    a = _random_boxes(rng, 2000, spread=1.0)
    b = _random_boxes(rng, 2000, spread=1.0)
    assert (bev_iou_exceeds(a, b, 0.2) == (bev_iou_aligned(a, b) > 0.2)).all()
    assert sum(calls) < 20


def _all_pairs(boxes):
    return np.repeat(boxes, len(boxes), 0), np.tile(boxes, (len(boxes), 1))


def test_degenerate_and_nan_boxes_without_warnings():
    boxes = np.array([[0, 0, 0.0, 2.0, 0.3], [0, 0, 2.0, -1.0, 0.3], [np.nan, 0, 2, 2, 0],
                      [0, 0, 2.0, 2.0, np.nan], [0, 0, 2.0, 2.0, 0.3]])
    a, b = _all_pairs(boxes)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = bev_iou_exceeds(a, b, 0.5)
    np.testing.assert_array_equal(got, bev_iou_aligned(a, b) > 0.5)
    assert got.sum() == 1  # the one solid box against itself
    assert bev_iou_exceeds(np.zeros((0, 5)), np.zeros((0, 5)), 0.5).shape == (0,)


def test_infinite_boxes_get_the_exact_clippings_answer():
    boxes = np.array([[0, 0, np.inf, 2, 0], [np.inf, 0, 2, 2, 0], [0, 0, 2, 2, np.inf], [0, 0, 2.0, 2.0, 0.3]])
    a, b = _all_pairs(boxes)
    with np.errstate(all="ignore"):
        np.testing.assert_array_equal(bev_iou_exceeds(a, b, 0.5), bev_iou_aligned(a, b) > 0.5)


def test_geometry_corners_follow_bev_corners():
    boxes = _random_boxes(np.random.default_rng(8), 50)
    g = box_geometry(boxes)
    want = bev_corners(np.zeros((50, 2)), boxes[:, 2:4], boxes[:, 4])
    np.testing.assert_allclose(g.corner_x.T, want[..., 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.corner_y.T, want[..., 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.edge_x, np.roll(g.corner_x, -1, 0) - g.corner_x, atol=1e-12)

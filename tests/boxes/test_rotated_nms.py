"""Rotated BEV/3D IoU against shapely polygons and known cases; rotated NMS against brute force."""

import warnings

import numpy as np
import pytest

from dsfec_jax.boxes.geometry import bev_corners
from dsfec_jax.boxes.nms import batched_rotated_nms, rotated_nms
from dsfec_jax.boxes.rotated_iou import bev_intersection, bev_iou, iou_3d

try:  # an independent reference for the clipping (dev extra); the known cases run without it
    from shapely.geometry import Polygon
except ImportError:
    Polygon = None

needs_shapely = pytest.mark.skipif(Polygon is None, reason="shapely not installed")
PI = np.pi


def _polygon(box):
    box = np.asarray(box, np.float64)
    return Polygon(bev_corners(box[None, :2], box[None, 2:4], box[4:5])[0])


def _shapely_iou(a, b) -> float:
    pa, pb = _polygon(a), _polygon(b)
    inter = pa.intersection(pb).area
    union = pa.area + pb.area - inter
    return inter / union if union > 0 else 0.0


def _pair_iou(a, b) -> float:
    """The brute-force NMS reference's IoU: shapely where available, else this library's."""
    return _shapely_iou(a, b) if Polygon is not None else float(bev_iou(a, b)[0, 0])


def _random_boxes(rng, n, spread=3.0):
    return np.c_[rng.uniform(-spread, spread, (n, 2)), rng.uniform(0.1, 5.0, (n, 2)),
                 rng.uniform(-PI, PI, n)]


def _snapped_boxes(rng, n):
    """Axis-aligned boxes on a half-metre lattice: many shared and collinear edges, the hard cases."""
    return np.c_[rng.integers(-4, 5, (n, 2)) / 2, rng.integers(1, 6, (n, 2)) / 2,
                 rng.integers(-2, 3, n) * PI / 2]


# ----------------------------------------------------------------------------- BEV IoU


@needs_shapely
def test_bev_iou_matches_shapely_on_random_pairs():
    rng = np.random.default_rng(0)
    a = np.r_[_random_boxes(rng, 300), _snapped_boxes(rng, 200)]
    b = np.r_[_random_boxes(rng, 300), _snapped_boxes(rng, 200)]
    b[::7, :2] = a[::7, :2]  # some concentric pairs: crossing shapes, nested boxes
    got = np.diagonal(bev_iou(a, b))
    want = np.array([_shapely_iou(p, q) for p, q in zip(a, b)])
    assert (want > 0).sum() > 200  # the pairs must actually overlap to test anything
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)


@needs_shapely
def test_bev_iou_pairwise_matrix_matches_shapely():
    rng = np.random.default_rng(1)
    a, b = _random_boxes(rng, 20), _random_boxes(rng, 30)
    want = np.array([[_shapely_iou(p, q) for q in b] for p in a])
    np.testing.assert_allclose(bev_iou(a, b), want, rtol=0, atol=1e-6)


@needs_shapely
def test_bev_iou_far_from_origin_matches_shapely_near_it():
    rng = np.random.default_rng(2)
    a, b = _random_boxes(rng, 50), _random_boxes(rng, 50)
    want = np.array([_shapely_iou(p, q) for p, q in zip(a, b)])
    shift = np.array([1e5, -3e4, 0, 0, 0])
    np.testing.assert_allclose(np.diagonal(bev_iou(a + shift, b + shift)), want, rtol=0, atol=1e-6)


@pytest.mark.parametrize("yaw", [0.0, 0.3, PI / 2, -2.0, PI])
def test_bev_iou_known_cases(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    square = np.array([1.0, -2.0, 2.0, 2.0, yaw])
    rect = np.array([1.0, -2.0, 1.0, 3.0, yaw])
    along = lambda d: square + [d * c, d * s, 0, 0, 0]  # noqa: E731 - shift along the heading
    turn = lambda box, angle: box + [0, 0, 0, 0, angle]  # noqa: E731
    cases = {
        "same": (square, square, 1.0),
        "square turned 90 degrees": (square, turn(square, PI / 2), 1.0),
        "rectangle turned 180 degrees": (rect, turn(rect, PI), 1.0),
        "rectangle turned 90 degrees": (rect, turn(rect, PI / 2), 1 / 5),  # 1x1 shared of 3 + 3 - 1
        "half overlap": (square, along(1.0), 1 / 3),
        "touching edge": (square, along(2.0), 0.0),
        "disjoint": (square, along(5.0), 0.0),
        "nested": (square, np.array([1.0, -2.0, 1.0, 1.0, yaw + 0.4]), 0.25),
    }
    for name, (first, other, want) in cases.items():
        assert bev_iou(first, other)[0, 0] == pytest.approx(want, abs=1e-9), name
        assert bev_iou(other, first)[0, 0] == pytest.approx(want, abs=1e-9), name


def test_bev_iou_same_boxes_is_one_and_symmetric():
    rng = np.random.default_rng(3)
    a, b = _random_boxes(rng, 40), np.r_[_random_boxes(rng, 20), _snapped_boxes(rng, 20)]
    np.testing.assert_allclose(np.diagonal(bev_iou(a, a)), 1.0, atol=1e-9)
    np.testing.assert_allclose(bev_iou(a, b), bev_iou(b, a).T, atol=1e-9)
    flipped = a + [0, 0, 0, 0, PI]  # heading reversed: the same rectangle
    np.testing.assert_allclose(np.diagonal(bev_iou(a, flipped)), 1.0, atol=1e-9)
    iou = bev_iou(a, b)
    assert np.all((iou >= 0) & (iou <= 1))


def test_bev_iou_corner_contact_and_shared_edge_are_zero():
    square = np.array([0.0, 0.0, 2.0, 2.0, 0.0])
    diamond = np.array([1 + np.sqrt(2), 0.0, 2.0, 2.0, PI / 4])  # its corner touches square's edge
    corner = np.array([2.0, 2.0, 2.0, 2.0, 0.0])
    assert bev_iou(square, np.stack([diamond, corner]))[0] == pytest.approx([0.0, 0.0], abs=1e-12)


def test_bev_iou_degenerate_boxes_are_zero_without_warnings():
    boxes = np.array([[0, 0, 0.0, 2.0, 0.3], [0, 0, 2.0, 0.0, 0.3], [0, 0, 0.0, 0.0, 0.0],
                      [0, 0, -1.0, 2.0, 0.0], [0, 0, 2.0, 2.0, 0.3]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's divide/invalid RuntimeWarnings become failures
        iou = bev_iou(boxes, boxes)
    want = np.zeros((5, 5))
    want[4, 4] = 1.0
    np.testing.assert_allclose(iou, want, atol=1e-12)


def test_bev_iou_shapes():
    rng = np.random.default_rng(4)
    a = _random_boxes(rng, 3)
    assert bev_iou(a, np.zeros((0, 5))).shape == (3, 0)
    assert bev_iou(np.zeros((0, 5)), a).shape == (0, 3)
    assert bev_iou(a[0], a).shape == (1, 3)
    assert bev_iou(a.astype(np.float32), a).dtype == np.float64
    with pytest.raises(ValueError):
        bev_iou(np.zeros((3, 7)), a)


@needs_shapely
def test_bev_intersection_area_matches_shapely():
    rng = np.random.default_rng(5)
    a, b = _random_boxes(rng, 100), _random_boxes(rng, 100)
    want = [_polygon(p).intersection(_polygon(q)).area for p, q in zip(a, b)]
    np.testing.assert_allclose(np.diagonal(bev_intersection(a, b)), want, rtol=0, atol=1e-6)


# ----------------------------------------------------------------------------- 3D IoU


def _box3d(x=0.0, y=0.0, z=0.0, w=2.0, l=4.0, h=2.0, yaw=0.3):  # noqa: E741 - l is the box length
    return np.array([x, y, z, w, l, h, yaw])


@pytest.mark.parametrize("other, want", [
    (_box3d(), 1.0),
    (_box3d(z=1.0), 1 / 3),                   # half the height shared: h/2 / (2h - h/2)
    (_box3d(z=2.0), 0.0),                     # stacked, touching
    (_box3d(z=5.0), 0.0),                     # above
    (_box3d(h=1.0), 0.5),                     # same footprint, half as tall, centred
    (_box3d(z=1.4, h=1.0), 0.1 / 2.9),        # 0.1 m overlap; z is the centre, not the bottom
    (_box3d(w=1.0, l=2.0, h=1.0, yaw=0.5), 1 / 8),  # nested inside
    (_box3d(x=20.0), 0.0),                    # far apart in BEV
])
def test_iou_3d_known_cases(other, want):
    assert iou_3d(_box3d(), other)[0, 0] == pytest.approx(want, abs=1e-9)


@needs_shapely
def test_iou_3d_matches_shapely_times_height_overlap():
    rng = np.random.default_rng(6)
    n = 200
    a = np.c_[_random_boxes(rng, n)[:, :2], rng.uniform(-1, 1, n), rng.uniform(0.1, 5, (n, 2)),
              rng.uniform(0.2, 3, n), rng.uniform(-PI, PI, n)]
    b = np.c_[_random_boxes(rng, n)[:, :2], rng.uniform(-1, 1, n), rng.uniform(0.1, 5, (n, 2)),
              rng.uniform(0.2, 3, n), rng.uniform(-PI, PI, n)]
    want = []
    for p, q in zip(a, b):
        area = _polygon(p[[0, 1, 3, 4, 6]]).intersection(_polygon(q[[0, 1, 3, 4, 6]])).area
        dz = max(0.0, min(p[2] + p[5] / 2, q[2] + q[5] / 2) - max(p[2] - p[5] / 2, q[2] - q[5] / 2))
        inter = area * dz
        want.append(inter / (np.prod(p[3:6]) + np.prod(q[3:6]) - inter))
    np.testing.assert_allclose(np.diagonal(iou_3d(a, b)), want, rtol=0, atol=1e-6)


def test_iou_3d_degenerate_boxes_are_zero_without_warnings():
    boxes = np.stack([_box3d(h=0.0), _box3d(w=0.0), _box3d(l=0.0, h=0.0), _box3d()])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        iou = iou_3d(boxes, boxes)
    want = np.zeros((4, 4))
    want[3, 3] = 1.0
    np.testing.assert_allclose(iou, want, atol=1e-12)


# ----------------------------------------------------------------------------- NMS


def _ref_nms(boxes, scores, threshold, idx=None):
    """Brute-force greedy NMS with plain loops: best score first, ties to the lower index."""
    idx = range(len(scores)) if idx is None else idx
    keep = []
    for i in sorted(idx, key=lambda i: (-scores[i], i)):
        if all(_pair_iou(boxes[i], boxes[k]) <= threshold for k in keep):
            keep.append(i)
    return keep


def _scene(rng, n=60, clusters=8):
    """Boxes jittered around a few objects (so suppression happens), with tied scores."""
    centres = _random_boxes(rng, clusters, spread=6.0)
    pick = rng.integers(0, clusters, n)
    boxes = centres[pick] + np.c_[rng.normal(0, 0.4, (n, 2)), rng.normal(0, 0.3, (n, 2)),
                                  rng.normal(0, 0.3, n)]
    boxes[:, 2:4] = np.abs(boxes[:, 2:4]) + 0.1
    boxes[n - 5:] = boxes[:5]  # exact duplicates...
    scores = np.round(rng.uniform(0, 1, n), 1)  # ...and many tied scores
    return boxes, scores


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("threshold", [0.0, 0.1, 0.3, 0.5, 0.8])
def test_rotated_nms_matches_brute_force(seed, threshold):
    boxes, scores = _scene(np.random.default_rng(seed))
    keep = rotated_nms(boxes, scores, threshold)
    assert keep.dtype == np.int64
    assert keep.tolist() == _ref_nms(boxes, scores, threshold)


def test_rotated_nms_order_and_threshold_respected():
    boxes, scores = _scene(np.random.default_rng(10), n=80)
    keep = rotated_nms(boxes, scores, 0.3)
    assert np.all(np.diff(scores[keep]) <= 0)
    iou = bev_iou(boxes[keep], boxes[keep])
    assert np.all(iou[~np.eye(len(keep), dtype=bool)] <= 0.3)
    suppressed = np.setdiff1d(np.arange(len(boxes)), keep)
    assert np.all(bev_iou(boxes[suppressed], boxes[keep]).max(1) > 0.3)  # each beaten by a kept box


def test_rotated_nms_ties_keep_the_lower_index():
    box = np.array([[0.0, 0.0, 2.0, 4.0, 0.1]] * 3)
    assert rotated_nms(box, np.array([0.5, 0.9, 0.9]), 0.5).tolist() == [1]
    assert rotated_nms(box, np.array([0.5, 0.9, 0.9]), 1.0).tolist() == [1, 2, 0]


def test_rotated_nms_max_output_score_threshold_and_top_k():
    boxes, scores = _scene(np.random.default_rng(11), n=80)
    full = rotated_nms(boxes, scores, 0.2)
    assert len(full) > 5
    assert rotated_nms(boxes, scores, 0.2, max_output=5).tolist() == full[:5].tolist()
    assert rotated_nms(boxes, scores, 0.2, max_output=0).size == 0

    keep = rotated_nms(boxes, scores, 0.2, score_threshold=0.45)
    assert np.all(scores[keep] > 0.45)
    assert keep.tolist() == _ref_nms(boxes, scores, 0.2, np.flatnonzero(scores > 0.45))

    top = sorted(range(len(scores)), key=lambda i: (-scores[i], i))[:20]
    assert rotated_nms(boxes, scores, 0.2, pre_top_k=20).tolist() == _ref_nms(boxes, scores, 0.2, top)


def test_rotated_nms_edge_inputs():
    assert rotated_nms(np.zeros((0, 5)), np.zeros(0), 0.5).tolist() == []
    boxes = np.array([[0, 0, 2, 4, 0.0], [0.1, 0, 2, 4, 0.0], [9, 9, 2, 4, 0.0]])
    assert rotated_nms(boxes, np.array([0.2, np.nan, 0.1]), 0.5).tolist() == [0, 2]
    with pytest.raises(ValueError):
        rotated_nms(boxes, np.ones(3), 1.5)


@pytest.mark.parametrize("seed", range(3))
def test_batched_rotated_nms_is_per_class(seed):
    rng = np.random.default_rng(seed + 20)
    boxes, scores = _scene(rng, n=60)
    labels = rng.integers(0, 3, len(boxes))
    keep = batched_rotated_nms(boxes, scores, labels, 0.3)
    want = [i for c in range(3) for i in _ref_nms(boxes, scores, 0.3, np.flatnonzero(labels == c))]
    assert keep.tolist() == sorted(want, key=lambda i: (-scores[i], i))
    assert batched_rotated_nms(boxes, scores, labels, 0.3, max_output=7).tolist() == keep[:7].tolist()


def test_batched_rotated_nms_classes_never_suppress_each_other():
    boxes = np.array([[0.0, 0.0, 2.0, 4.0, 0.2]] * 4)
    scores = np.array([0.9, 0.8, 0.7, 0.6])
    assert batched_rotated_nms(boxes, scores, np.array([0, 1, 0, 2]), 0.5).tolist() == [0, 1, 3]
    assert batched_rotated_nms(np.zeros((0, 5)), np.zeros(0), np.zeros(0, int), 0.5).tolist() == []


def test_rotated_nms_thousand_boxes_matches_matrix_greedy():
    """A realistic 1000-box scene against greedy NMS on the full IoU matrix (no pruning)."""
    rng = np.random.default_rng(30)
    centres = np.c_[rng.uniform(0, 50, (100, 2)), rng.uniform(0.5, 2, 100), rng.uniform(1, 5, 100),
                    rng.uniform(-PI, PI, 100)]
    boxes = centres[rng.integers(0, 100, 1000)] + np.c_[rng.normal(0, 0.5, (1000, 2)),
                                                        np.zeros((1000, 2)), rng.normal(0, 0.2, 1000)]
    scores = rng.uniform(0, 1, 1000)
    order = np.argsort(-scores, kind="stable")
    iou = bev_iou(boxes[order], boxes[order])
    alive, want = np.ones(1000, bool), []
    for r in range(1000):
        if alive[r]:
            want.append(order[r])
            alive &= iou[r] <= 0.5
    assert rotated_nms(boxes, scores, 0.5).tolist() == want

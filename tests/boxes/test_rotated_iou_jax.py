"""jax aligned-pair rotated IoU: against the float64 numpy version, known cases, edge cases, jit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax.boxes.rotated_iou import bev_intersection, bev_iou, iou_3d
from dsfec_jax.boxes.rotated_iou_jax import (_clip_half_plane, bev_intersection_aligned, bev_iou_aligned,
                                             iou_3d_aligned)

PI = np.pi
BEV = [0, 1, 3, 4, 6]
TOL = dict(rtol=1e-4, atol=2e-5)  # float32 against float64
N = 256  # every call uses this many pairs: each new shape is a ~1 s XLA compile on CPU


def _f32(boxes):
    return np.asarray(boxes, np.float32)


def _padded(fn, a, b):
    """fn on the pairs a, b padded to N rows with all-zero boxes; the first len(a) results."""
    a, b = _f32(a), _f32(b)
    pad = np.zeros((N - len(a), a.shape[1]), np.float32)
    return np.asarray(fn(np.r_[a, pad], np.r_[b, pad]))[:len(a)]


def _iou3d(a, b):
    return _padded(iou_3d_aligned, a, b)


def _bev_iou(a, b):
    return _padded(bev_iou_aligned, _f32(a)[:, BEV], _f32(b)[:, BEV])


def _overlapping_pairs(rng, n=N):
    """Random 3D box pairs whose centres are close enough that most overlap partially."""
    a = np.c_[rng.uniform(-40, 40, (n, 2)), rng.uniform(-2, 2, n), rng.uniform(0.3, 5.0, (n, 3)),
              rng.uniform(-PI, PI, n)]
    b = np.c_[a[:, :3] + rng.uniform(-1.5, 1.5, (n, 3)), rng.uniform(0.3, 5.0, (n, 3)),
              rng.uniform(-PI, PI, n)]
    return _f32(a), _f32(b)


def _cube(x=0.0, y=0.0, z=0.0, w=1.0, l=1.0, h=1.0, yaw=0.0):
    return [x, y, z, w, l, h, yaw]


def test_random_pairs_match_numpy():
    a, b = _overlapping_pairs(np.random.default_rng(0))
    ref = np.diag(iou_3d(a, b))  # the float64 reference on the very float32 inputs
    assert np.mean((ref > 0.01) & (ref < 0.99)) > 0.7  # the cases compared are mostly partial overlaps
    np.testing.assert_allclose(iou_3d_aligned(a, b), ref, **TOL)
    a_bev, b_bev = a[:, BEV], b[:, BEV]
    np.testing.assert_allclose(bev_iou_aligned(a_bev, b_bev), np.diag(bev_iou(a_bev, b_bev)), **TOL)
    ref = np.diag(bev_intersection(a_bev, b_bev))
    np.testing.assert_allclose(bev_intersection_aligned(a_bev, b_bev), ref, **TOL)


def test_collinear_edges_match_numpy():
    # Yaws equal up to right angles and offsets on a coarse grid along the boxes' own axes put
    # edges on common lines: near-zero side tests, where rounding can add spurious crossings.
    rng = np.random.default_rng(1)
    yaw = rng.uniform(-PI, PI, N)
    a = np.c_[rng.integers(-2, 3, (N, 2)) * 0.5, np.zeros(N), rng.integers(1, 5, (N, 3)) * 0.5, yaw]
    b = np.c_[rng.integers(-2, 3, (N, 3)) * 0.5, rng.integers(1, 5, (N, 3)) * 0.5,
              yaw + rng.integers(-2, 3, N) * PI / 2]
    c, s = np.cos(yaw), np.sin(yaw)
    for boxes in (a, b):
        boxes[:, :2] = np.c_[c * boxes[:, 0] - s * boxes[:, 1], s * boxes[:, 0] + c * boxes[:, 1]]
    a, b = _f32(a), _f32(b)
    got = np.asarray(iou_3d_aligned(a, b))
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, np.diag(iou_3d(a, b)), **TOL)


def test_identical_boxes_give_one():
    boxes = [_cube(), _cube(x=63.7, y=-21.3, z=-1.2, w=1.8, l=4.4, h=1.6, yaw=2.1),
             _cube(w=0.6, l=0.8, h=1.7, yaw=-PI / 4), _cube(w=3.0, l=3.0, yaw=PI)]
    np.testing.assert_allclose(_iou3d(boxes, boxes), 1.0, rtol=1e-5)
    np.testing.assert_allclose(_bev_iou(boxes, boxes), 1.0, rtol=1e-5)


def test_disjoint_and_touching_boxes_give_zero():
    b = [_cube(x=3.0, yaw=0.7),        # apart in BEV
         _cube(z=1.5),                 # BEV identical, apart in height
         _cube(x=1.0),                 # sharing an edge
         _cube(x=1.0, y=1.0),          # sharing a corner
         _cube(z=1.0)]                 # stacked: sharing a face
    got = _iou3d([_cube()] * len(b), b)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, 0.0, atol=1e-6)


def test_box_inside_another_gives_volume_ratio():
    outer = _cube(x=10.0, y=5.0, z=0.5, w=4.0, l=6.0, h=3.0, yaw=0.3)
    inner = _cube(x=10.2, y=5.1, z=0.2, w=1.0, l=2.0, h=1.5, yaw=1.1)  # well inside: radius ~1.1 m
    ratio = (1.0 * 2.0 * 1.5) / (4.0 * 6.0 * 3.0)
    np.testing.assert_allclose(_iou3d([outer, inner], [inner, outer]), ratio, rtol=1e-5)
    # A thin slab 1 km above a tall box's centre: z +- h/2 rounds outwards by an ulp of 1000 m,
    # more than the slab's height, and the overlap must still not exceed that height.
    tall, slab = _cube(h=1e4), _cube(z=1e3, h=6.2e-5)
    np.testing.assert_allclose(_iou3d([tall], [slab]), 6.2e-5 / 1e4, rtol=1e-5)


def test_square_turned_45_degrees_has_analytic_overlap():
    # Two unit squares on one centre, one turned 45 deg: the overlap is a regular octagon of
    # area 2 (sqrt 2 - 1); heights equal, so the 3D IoU is the BEV IoU.
    inter = 2 * (np.sqrt(2) - 1)
    a, b = _f32([_cube()]), _f32([_cube(yaw=PI / 4)])
    np.testing.assert_allclose(_padded(bev_intersection_aligned, a[:, BEV], b[:, BEV]), [inter], rtol=1e-5)
    np.testing.assert_allclose(_iou3d(a, b), [inter / (2 - inter)], rtol=1e-5)


def test_degenerate_and_non_finite_boxes_give_zero():
    good = _cube(w=2.0, l=3.0, h=1.5, yaw=0.4)
    bad = [_cube(w=0.0, l=3.0, h=1.5), _cube(w=2.0, l=3.0, h=0.0), _cube(w=2.0, l=0.0, h=1.5),
           _cube(w=-2.0, l=3.0, h=1.5), _cube(w=-2.0, l=-3.0, h=1.5), [0.0] * 7,
           _cube(w=np.inf, l=3.0), _cube(x=np.nan)]
    n = len(bad)
    for a, b in [(bad, [good] * n), ([good] * n, bad), (bad, bad)]:
        got = _iou3d(a, b)
        assert np.isfinite(got).all()
        np.testing.assert_array_equal(got, 0.0)
        # A zero height is no BEV degeneracy.
        for got in (_bev_iou(a, b), _padded(bev_intersection_aligned, _f32(a)[:, BEV], _f32(b)[:, BEV])):
            assert np.isfinite(got).all()
            np.testing.assert_array_equal(np.delete(got, 1), 0.0)


def test_extreme_values_stay_finite_and_in_unit_interval():
    # Diverged predictions: sizes and offsets from 1e-20 to 1e20 (float32 products overflow),
    # zero and negative sizes; half the pairs identical. The target must stay in [0, 1].
    rng = np.random.default_rng(3)
    for _ in range(4):
        scale = lambda *shape: 10.0 ** rng.uniform(-20, 20, shape)  # noqa: E731
        a = np.c_[rng.normal(size=(N, 3)) * scale(N, 1), scale(N, 3) * rng.choice([-1, 0, 1, 1, 1], (N, 3)),
                  rng.uniform(-1e3, 1e3, N)]
        b = np.c_[rng.normal(size=(N, 3)) * scale(N, 1), scale(N, 3), rng.uniform(-1e3, 1e3, N)]
        b[::2] = a[::2]
        for got in (iou_3d_aligned(_f32(a), _f32(b)), bev_iou_aligned(_f32(a)[:, BEV], _f32(b)[:, BEV])):
            got = np.asarray(got)
            assert np.isfinite(got).all() and got.min() >= 0.0 and got.max() <= 1.0


def test_clipping_never_drops_a_vertex():
    # Rounding near a clip line can make a convex polygon's side signs alternate; the output
    # (each inside vertex plus each crossing) must still fit: here 2 inside + 4 crossings.
    square = jnp.asarray([[[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]]])
    side = jnp.asarray([[1e-7, -1e-7, 1e-7, -1e-7]])
    poly, valid = jax.jit(_clip_half_plane)(square, jnp.ones((1, 4), bool), side)
    assert int(valid.sum()) == 6
    assert np.isfinite(np.asarray(poly)).all()


def test_runs_under_jit_on_batch_dims():
    # Leading dims (2, 8, 16) against 16 boxes, broadcast, inside an outer jit: each of the 16
    # boxes meets 16 jittered copies of itself.
    rng = np.random.default_rng(2)
    b = _overlapping_pairs(rng, 16)[0]
    a = b + np.c_[rng.uniform(-1, 1, (2, 8, 16, 3)), rng.uniform(-0.3, 0.3, (2, 8, 16, 3)),
                  rng.uniform(-1, 1, (2, 8, 16, 1))]
    a = _f32(a)
    got = jax.jit(iou_3d_aligned)(jnp.asarray(a), jnp.asarray(b))
    assert got.shape == (2, 8, 16) and got.dtype == jnp.float32
    ref = np.diag(iou_3d(a.reshape(-1, 7), np.tile(b, (16, 1))))
    assert np.mean(ref > 0) > 0.7
    np.testing.assert_allclose(np.asarray(got).reshape(-1), ref, **TOL)


def test_wrong_box_width_is_rejected():
    with pytest.raises(ValueError, match=r"\(\.\.\., 7\)"):
        iou_3d_aligned(np.zeros((3, 5)), np.zeros((3, 5)))

"""Exact IoU of oriented boxes for aligned pairs, in jit-able jax.numpy.

The jax counterpart of `rotated_iou` for pairs ``a[i], b[i]`` (not all-against-all), meant for
training targets: fixed shapes, no Python loops over boxes, no data-dependent control flow.

Box layouts (metres, radians), the conventions of `geometry.bev_corners`:

- BEV box: ``(x, y, w, l, yaw)`` -- centre, width across the heading, length along it, heading
  (about +z, from +x).
- 3D box: ``(x, y, z, w, l, h, yaw)`` -- as above, ``z`` the box *centre* and ``h`` its height.

Method: as in the numpy version, box a's rectangle is clipped by the four edges of box b's
(Sutherland-Hodgman) and the clipped polygon is measured by the shoelace formula. To keep shapes
static, every polygon lives in a padded (..., V, 2) array with a validity mask: after each clip the
kept vertices are moved to the front in order and the tail is filled with copies of the first
vertex, which adds only zero-length edges and so changes neither the clipping nor the area.

V grows with each clip to a bound that no rounding can exceed: clipping a V-gon by a half-plane
keeps its i inside vertices plus one point per crossing edge, and each crossing edge has one inside
and one outside end, so the result has at most min(3 i, 2 V - i) <= 3 V / 2 vertices. Exact
arithmetic gives at most 8 (4 -> 5 -> 6 -> 7 -> 8), but near-collinear edges can add spurious
crossings; the bound (4 -> 6 -> 9 -> 13 -> 19) means no vertex is ever dropped.

3D IoU = BEV overlap area x height-interval overlap / (vol_a + vol_b - overlap volume). Degenerate
boxes (any size <= 0) and boxes with non-finite entries have IoU 0. Leading batch dimensions are
broadcast between a and b. Results are float32 for float32 (or integer) inputs. The public
functions are jitted (one compile per input shape) and can be called inside other jitted code.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

BEV_COLUMNS = (0, 1, 3, 4, 6)  # (x, y, w, l, yaw) within (x, y, z, w, l, h, yaw)


@jax.jit
def bev_intersection_aligned(boxes_a, boxes_b) -> jnp.ndarray:
    """(...,) BEV overlap areas of aligned pairs of boxes ``(x, y, w, l, yaw)``, shapes (..., 5)."""
    a, b = _as_pairs(boxes_a, boxes_b, 5)
    return _bev_intersection(a, b)


@jax.jit
def bev_iou_aligned(boxes_a, boxes_b) -> jnp.ndarray:
    """(...,) BEV IoU of aligned pairs of boxes ``(x, y, w, l, yaw)``, shapes (..., 5)."""
    a, b = _as_pairs(boxes_a, boxes_b, 5)
    inter = _bev_intersection(a, b)
    return _ratio(inter, _area(a[..., 2], a[..., 3]) + _area(b[..., 2], b[..., 3]) - inter)


@jax.jit
def iou_3d_aligned(boxes_a, boxes_b) -> jnp.ndarray:
    """(...,) 3D IoU of aligned pairs of boxes ``(x, y, z, w, l, h, yaw)`` (z = centre), shapes (..., 7).

    Boxes turn about the vertical axis only, so the overlap volume is the BEV overlap area times
    the overlap of the height intervals.
    """
    a, b = _as_pairs(boxes_a, boxes_b, 7)
    bev = jnp.asarray(BEV_COLUMNS)
    h_a, h_b = jnp.maximum(a[..., 5], 0.0), jnp.maximum(b[..., 5], 0.0)
    # Heights relative to a's centre, as in the BEV; the clamp to the shorter box keeps rounding
    # (a large z offset against a small height) from making the overlap exceed either height.
    dz = b[..., 2] - a[..., 2]
    top = jnp.minimum(h_a / 2, dz + h_b / 2)
    bottom = jnp.maximum(-h_a / 2, dz - h_b / 2)
    overlap = jnp.clip(top - bottom, 0.0, jnp.minimum(h_a, h_b))
    inter = _bev_intersection(a[..., bev], b[..., bev]) * overlap
    vol_a, vol_b = _area(a[..., 3], a[..., 4]) * h_a, _area(b[..., 3], b[..., 4]) * h_b
    return _ratio(inter, vol_a + vol_b - inter)


def _as_pairs(boxes_a, boxes_b, width: int):
    """Float arrays (..., width) of a common broadcast shape; non-finite boxes zeroed (degenerate)."""
    a, b = _as_float(boxes_a), _as_float(boxes_b)
    for boxes in (a, b):
        if boxes.ndim == 0 or boxes.shape[-1] != width:
            raise ValueError(f"expected boxes of shape (..., {width}), got {boxes.shape}")
    dtype = jnp.promote_types(a.dtype, b.dtype)
    shape = jnp.broadcast_shapes(a.shape, b.shape)
    return (_finite_or_zero(jnp.broadcast_to(a.astype(dtype), shape)),
            _finite_or_zero(jnp.broadcast_to(b.astype(dtype), shape)))


def _as_float(boxes) -> jnp.ndarray:
    boxes = jnp.asarray(boxes)
    return boxes.astype(jnp.promote_types(boxes.dtype, jnp.float32))


def _finite_or_zero(boxes) -> jnp.ndarray:
    # A diverged prediction (inf/NaN size or centre) must give a target of 0, not NaN: an all-zero
    # box is degenerate, so it scores IoU 0 through the ordinary path.
    finite = jnp.all(jnp.isfinite(boxes), axis=-1, keepdims=True)
    return jnp.where(finite, boxes, 0.0)


def _area(w, l) -> jnp.ndarray:
    # A negative size is no box at all, not a box with negative area.
    return jnp.maximum(w, 0.0) * jnp.maximum(l, 0.0)


def _ratio(inter, union) -> jnp.ndarray:
    # Degenerate pairs have a zero union: IoU 0 rather than 0/0 (the inner where keeps the unused
    # branch finite too).
    positive = union > 0
    return jnp.where(positive, inter / jnp.where(positive, union, 1.0), 0.0)


def _bev_intersection(a, b) -> jnp.ndarray:
    """(...,) overlap areas of aligned BEV box pairs (..., 5)."""
    # Work relative to a's centre: boxes far from the origin then lose no precision to cancellation.
    rel = b[..., :2] - a[..., :2]
    subject = _corners(jnp.zeros_like(rel), a[..., 2], a[..., 3], a[..., 4])
    clip = _corners(rel, b[..., 2], b[..., 3], b[..., 4])
    poly, valid = subject, jnp.ones(subject.shape[:-1], bool)
    for e in range(4):  # the four edges of b: a static loop, unrolled at trace time
        start, end = clip[..., e, :], clip[..., (e + 1) % 4, :]
        poly, valid = _clip_half_plane(poly, valid, _side(poly, start, end))
    area = jnp.where(valid.sum(-1) >= 3, _shoelace(poly), 0.0)
    # Rounding on shared edges can overshoot; the overlap can never exceed the smaller box.
    area_a, area_b = a[..., 2] * a[..., 3], b[..., 2] * b[..., 3]
    solid = (a[..., 2] > 0) & (a[..., 3] > 0) & (b[..., 2] > 0) & (b[..., 3] > 0)
    return jnp.where(solid, jnp.clip(area, 0.0, jnp.minimum(area_a, area_b)), 0.0)


def _corners(center_xy, w, l, yaw) -> jnp.ndarray:
    """(..., 4, 2) BEV corners, counter-clockwise, as `geometry.bev_corners` orders them."""
    half_l, half_w = l / 2, w / 2
    along = jnp.stack([half_l, -half_l, -half_l, half_l], -1)  # local x: along the heading
    across = jnp.stack([half_w, half_w, -half_w, -half_w], -1)  # local y: across it
    c, s = jnp.cos(yaw)[..., None], jnp.sin(yaw)[..., None]
    x = along * c - across * s + center_xy[..., None, 0]
    y = along * s + across * c + center_xy[..., None, 1]
    return jnp.stack([x, y], -1)


def _side(poly, start, end) -> jnp.ndarray:
    """(..., V) cross product of the edge start->end with start->vertex: >= 0 on its left, inside
    a counter-clockwise polygon."""
    edge = (end - start)[..., None, :]
    rel = poly - start[..., None, :]
    return edge[..., 0] * rel[..., 1] - edge[..., 1] * rel[..., 0]


def _clip_half_plane(poly, valid, side):
    """One Sutherland-Hodgman step on padded polygons (..., V, 2) with masks (..., V): keep each
    inside vertex and add the crossing point on each edge that crosses the line."""
    n = poly.shape[-2]
    # Valid vertices sit at the front and the padding repeats vertex 0, so the cyclic successor
    # in the array is the polygon's successor (the last valid vertex's is the copy of vertex 0).
    nxt_poly, nxt_side = jnp.roll(poly, -1, axis=-2), jnp.roll(side, -1, axis=-1)
    inside = side >= 0
    crosses = inside != (nxt_side >= 0)
    # On a crossing edge one side is >= 0 and the other < 0, so the denominator is never zero;
    # elsewhere it is replaced by 1 so the discarded value stays finite too.
    t = side / jnp.where(crosses, side - nxt_side, 1.0)
    crossing = poly + t[..., None] * (nxt_poly - poly)
    # Per vertex: (the vertex, the crossing on its outgoing edge), interleaved in polygon order.
    cand = jnp.stack([poly, crossing], -2).reshape(*poly.shape[:-2], 2 * n, 2)
    keep = jnp.stack([inside & valid, crosses & valid], -1).reshape(*poly.shape[:-2], 2 * n)
    return _compact(cand, keep, capacity=3 * n // 2)


def _compact(cand, keep, capacity: int):
    """Move the kept candidates (..., C, 2) to the front, in order, into `capacity` slots padded
    with the first kept one. `capacity` must bound the number kept (see the module docstring)."""
    rank = jnp.cumsum(keep, axis=-1)  # inclusive: the k-th kept candidate (from 0) has rank k + 1
    count = rank[..., -1:]
    slots = jnp.arange(capacity)
    # Slot k takes the candidate just after all those of rank <= k, i.e. the k-th kept one.
    src = jnp.sum(rank[..., None, :] <= slots[:, None], axis=-1)
    filled = slots < count
    # Padding (and an empty polygon's every slot) points at the first kept candidate; the clamp
    # keeps an empty polygon's index in range, where it yields some finite, masked-out point.
    src = jnp.minimum(jnp.where(filled, src, src[..., :1]), cand.shape[-2] - 1)
    return jnp.take_along_axis(cand, src[..., None], axis=-2), filled


def _shoelace(poly) -> jnp.ndarray:
    """(...,) signed areas of polygons (..., V, 2), positive when counter-clockwise."""
    x, y = poly[..., 0], poly[..., 1]
    return 0.5 * jnp.sum(x * jnp.roll(y, -1, -1) - jnp.roll(x, -1, -1) * y, axis=-1)

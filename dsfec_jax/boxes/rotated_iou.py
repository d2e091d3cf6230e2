"""Exact IoU of oriented boxes: BEV rectangles clipped by convex polygon clipping, in numpy.

Box layouts (metres, radians), the conventions of `geometry.bev_corners`:

- BEV box: ``(x, y, w, l, yaw)`` -- centre, width across the heading, length along it, heading.
- 3D box: ``(x, y, z, w, l, h, yaw)`` -- as above, ``z`` the box *centre* and ``h`` its height.

The intersection of two rectangles is found by Sutherland-Hodgman clipping of one rectangle by the
four edges of the other and measured by the shoelace formula; every pair is clipped at once on
padded (pairs, vertices, 2) arrays. Degenerate boxes (a zero or negative size) have IoU 0.
"""

from __future__ import annotations

import numpy as np

from dsfec_jax.boxes.geometry import bev_corners

PAIR_CHUNK = 32768  # pairs clipped at once: bounds the clipping temporaries to a few tens of MB


def bev_iou(boxes_a, boxes_b) -> np.ndarray:
    """(M, K) BEV IoU of boxes ``(x, y, w, l, yaw)``: (M, 5) against (K, 5)."""
    a, b = _as_boxes(boxes_a, 5), _as_boxes(boxes_b, 5)
    inter = bev_intersection(a, b)
    area_a, area_b = _area(a[:, 2], a[:, 3]), _area(b[:, 2], b[:, 3])
    return _ratio(inter, area_a[:, None] + area_b[None, :] - inter)


def bev_iou_aligned(boxes_a, boxes_b) -> np.ndarray:
    """(P,) BEV IoU of the aligned pairs a[p], b[p] (both (P, 5)): bitwise `bev_iou(a, b)`'s
    diagonal, since every pair goes through the same per-pair arithmetic; for callers that need a
    few scattered pairs (greedy NMS) rather than a whole matrix."""
    a, b = _as_boxes(boxes_a, 5), _as_boxes(boxes_b, 5)
    if len(a) != len(b):
        raise ValueError(f"expected as many boxes_b as boxes_a (aligned pairs), got {len(b)} and {len(a)}")
    inter = np.zeros(len(a))
    pairs = np.flatnonzero(may_touch(a, b))
    for s in range(0, len(pairs), PAIR_CHUNK):
        p = pairs[s:s + PAIR_CHUNK]
        inter[p] = _pair_intersection(a[p], b[p])
    return _ratio(inter, _area(a[:, 2], a[:, 3]) + _area(b[:, 2], b[:, 3]) - inter)


def may_touch(boxes_a, boxes_b) -> np.ndarray:
    """Bool, broadcast over the leading axes of boxes_a (..., 5) and boxes_b (..., 5): both boxes
    have a positive area and their circumscribed circles meet. A pair failing it has no overlap, so
    its IoU is exactly 0; every IoU here clips only the pairs that pass it."""
    solid = (_area(boxes_a[..., 2], boxes_a[..., 3]) > 0) & (_area(boxes_b[..., 2], boxes_b[..., 3]) > 0)
    return solid & circles_meet(boxes_a[..., 0] - boxes_b[..., 0], boxes_a[..., 1] - boxes_b[..., 1],
                                circumradius(boxes_a), circumradius(boxes_b))


def circumradius(boxes) -> np.ndarray:
    """Radius of the circle through the corners of BEV boxes (..., 5)."""
    return np.hypot(boxes[..., 2], boxes[..., 3]) / 2


def circles_meet(dx, dy, radius_a, radius_b) -> np.ndarray:
    """Circles of these radii with centres (dx, dy) apart meet; the relative 1e-9 of slack keeps
    rounding from separating circles that touch."""
    dist2 = np.square(dx)
    dist2 += np.square(dy)
    reach2 = np.add(radius_a, radius_b)
    reach2 *= reach2
    reach2 *= 1 + 1e-9  # in place, fewer temporaries: the values of dx**2 + dy**2 <= reach*reach*(1 + 1e-9)
    return dist2 <= reach2


def iou_3d(boxes_a, boxes_b) -> np.ndarray:
    """(M, K) 3D IoU of boxes ``(x, y, z, w, l, h, yaw)`` (z = centre), as the VoD/KITTI 3D AP uses.

    Boxes turn about the vertical axis only, so the overlap volume is the BEV overlap area times
    the overlap of the height intervals.
    """
    a, b = _as_boxes(boxes_a, 7), _as_boxes(boxes_b, 7)
    bev = [0, 1, 3, 4, 6]
    h_a, h_b = np.maximum(a[:, 5], 0.0), np.maximum(b[:, 5], 0.0)
    top = np.minimum((a[:, 2] + h_a / 2)[:, None], (b[:, 2] + h_b / 2)[None, :])
    bottom = np.maximum((a[:, 2] - h_a / 2)[:, None], (b[:, 2] - h_b / 2)[None, :])
    inter = bev_intersection(a[:, bev], b[:, bev]) * np.maximum(top - bottom, 0.0)
    vol_a, vol_b = _area(a[:, 3], a[:, 4]) * h_a, _area(b[:, 3], b[:, 4]) * h_b
    return _ratio(inter, vol_a[:, None] + vol_b[None, :] - inter)


def bev_intersection(boxes_a, boxes_b) -> np.ndarray:
    """(M, K) overlap areas of BEV boxes ``(x, y, w, l, yaw)``; only pairs that can touch are clipped."""
    a, b = _as_boxes(boxes_a, 5), _as_boxes(boxes_b, 5)
    inter = np.zeros((len(a), len(b)))
    ia, ib = _candidate_pairs(a, b)
    for s in range(0, len(ia), PAIR_CHUNK):
        i, j = ia[s:s + PAIR_CHUNK], ib[s:s + PAIR_CHUNK]
        inter[i, j] = _pair_intersection(a[i], b[j])
    return inter


def _as_boxes(boxes, width: int) -> np.ndarray:
    """float64 (N, width); a single box (width,) becomes (1, width)."""
    boxes = np.asarray(boxes, np.float64)
    if boxes.ndim == 1:
        boxes = boxes[None]
    if boxes.ndim != 2 or boxes.shape[1] != width:
        raise ValueError(f"expected boxes of shape (N, {width}), got {boxes.shape}")
    return boxes


def _area(w, l) -> np.ndarray:
    # A negative size is no box at all, not a box with negative area.
    return np.maximum(w, 0.0) * np.maximum(l, 0.0)


def _ratio(inter, union) -> np.ndarray:
    # Degenerate pairs have a zero union: IoU 0 rather than 0/0.
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def _candidate_pairs(a, b):
    """Index pairs of the boxes that `may_touch`: all others have zero overlap, so clipping only
    these keeps sparse scenes cheap."""
    return np.nonzero(may_touch(a[:, None], b[None, :]))


def _pair_intersection(a, b) -> np.ndarray:
    """(P,) overlap areas of aligned box pairs a[p], b[p] of positive size."""
    # Work relative to a's centre: boxes far from the origin then lose no precision to cancellation.
    rel = b[:, :2] - a[:, :2]
    subject = bev_corners(np.zeros_like(rel), a[:, 2:4], a[:, 4])
    clip = bev_corners(rel, b[:, 2:4], b[:, 4])
    area = _shoelace(_clip(subject, clip))
    # Rounding on shared edges can overshoot; the overlap can never exceed the smaller box.
    smaller = np.minimum(a[:, 2] * a[:, 3], b[:, 2] * b[:, 3])
    return np.clip(area, 0.0, smaller)


def _clip(subject, clip) -> np.ndarray:
    """Sutherland-Hodgman: clip convex polygons subject (P, N, 2) by counter-clockwise quads clip (P, 4, 2).

    Polygons are padded to a common vertex count with copies of their first vertex, so the padding
    adds zero-length edges only and `np.roll` gives every vertex its cyclic successor.
    """
    poly, count = subject, np.full(len(subject), subject.shape[1])
    for e in range(4):
        start, edge = clip[:, e], clip[:, (e + 1) % 4] - clip[:, e]
        rel = poly - start[:, None]
        side = edge[:, None, 0] * rel[..., 1] - edge[:, None, 1] * rel[..., 0]  # >= 0: left of edge, inside
        poly, count = _clip_half_plane(poly, count, side)
    return poly


def _clip_half_plane(poly, count, side):
    """One Sutherland-Hodgman step: keep each inside vertex, and add the crossing point on each
    edge that crosses the line; then compact the survivors to the front, in order."""
    n = poly.shape[1]
    nxt = np.arange(1, n + 1) % n
    inside = side >= 0
    crosses = inside != inside[:, nxt]
    # On a crossing edge one side is >= 0 and the other < 0, so the denominator is never zero.
    t = side / np.where(crosses, side - side[:, nxt], 1.0)
    cand = np.empty((len(poly), n, 2, 2))  # per vertex: (the vertex, the crossing on its edge)
    cand[:, :, 0] = poly
    cand[:, :, 1] = poly + t[..., None] * (poly[:, nxt] - poly)
    keep = np.stack([inside, crosses], 2) & (np.arange(n)[None, :, None] < count[:, None, None])
    return _compact(cand.reshape(len(poly), 2 * n, 2), keep.reshape(len(poly), 2 * n))


def _compact(cand, keep):
    """Move the kept candidates to the front (order kept), pad with the first vertex, trim the width."""
    count = keep.sum(1)
    width = max(int(count.max(initial=0)), 1)  # adaptive: never drops a vertex, even from rounding
    rows, cols = np.nonzero(keep)  # row-major, so each row's survivors come in polygon order
    slot = np.cumsum(keep, 1)[rows, cols] - 1
    poly = np.zeros((len(cand), width, 2))  # zeros, not empty: rows left with no vertex stay finite
    poly[rows, slot] = cand[rows, cols]
    pad = np.arange(width)[None] >= count[:, None]
    return np.where(pad[..., None], poly[:, :1], poly), count


def _shoelace(poly) -> np.ndarray:
    """(P,) signed areas of polygons (P, N, 2), positive when counter-clockwise.

    The terms are added strictly in vertex order (a cumulative sum): the padding then adds exact
    zeros, so a pair's area is the same to the last bit whatever the width of the batch it is
    clipped in. (`sum` switches to pairwise summation from 8 terms on, so a pair's last bit used to
    depend on the other pairs clipped with it; greedy NMS needs one answer per pair.)"""
    x, y = poly[..., 0], poly[..., 1]
    return 0.5 * np.cumsum(x * np.roll(y, -1, 1) - np.roll(x, -1, 1) * y, 1)[:, -1]

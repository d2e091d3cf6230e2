"""The greedy pass of rotated NMS as one compiled loop (numba), with the exact per-pair IoU of
`rotated_iou.bev_iou_aligned` written out in scalar form.

Why compiled: a DSFEC-S frame's NMS is a few hundred candidates and a few dozen kept boxes. In
numpy every step is a separate call, and right after the network has run (cold caches) those
~600 calls add up (the timings: docs/points-deploy.md); here the whole pass is one call.

Why the same answers: every IoU is computed with the arithmetic of `rotated_iou` in the same order
(corners, Sutherland-Hodgman clipping with the same side test, crossing formula and vertex order,
the shoelace terms summed in vertex order, the clip to the smaller area, the ratio) on float64,
with no fused multiply-adds (numba's default: no fastmath). The transcendental functions are the
one place a scalar library could round differently from numpy's vectorised ones, so cos, sin and
the circumradius (hypot) come in precomputed by numpy. Tests hold the IoUs bitwise equal to
`bev_iou_aligned` and the kept indices equal to the plain greedy pass.
"""

from __future__ import annotations

import numba
import numpy as np

# Vertex slots of the clipped polygon. Exact arithmetic gives at most 8 (a rectangle clipped by a
# rectangle), but rounding near shared edges can flip a side test more often; one half-plane step
# at most doubles the count (each vertex, plus one crossing on its edge), so 4 * 2^4 always fits.
POLY_SLOTS = 4 * 2 ** 4


@numba.njit(cache=True, nogil=True)
def _corners(cx, cy, w, l, c, s, out):
    """`geometry.bev_corners` of one box into out (4, 2), counter-clockwise, same arithmetic."""
    hl, hw = l / 2, w / 2
    lx = (hl, -hl, -hl, hl)
    ly = (hw, hw, -hw, -hw)
    for k in range(4):
        out[k, 0] = (lx[k] * c - ly[k] * s) + cx
        out[k, 1] = (lx[k] * s + ly[k] * c) + cy


@numba.njit(cache=True, nogil=True)
def pair_intersection(box_a, cos_a, sin_a, box_b, cos_b, sin_b, subject, clip, poly, nxt_poly, side):
    """`rotated_iou._pair_intersection` of one pair (both of positive size): the overlap area.
    subject, clip: (4, 2) scratch; poly, nxt_poly: (POLY_SLOTS, 2) scratch; side: (POLY_SLOTS,)."""
    _corners(0.0, 0.0, box_a[2], box_a[3], cos_a, sin_a, subject)
    _corners(box_b[0] - box_a[0], box_b[1] - box_a[1], box_b[2], box_b[3], cos_b, sin_b, clip)
    count = 4
    for k in range(4):
        poly[k, 0], poly[k, 1] = subject[k, 0], subject[k, 1]
    for e in range(4):
        sx, sy = clip[e, 0], clip[e, 1]
        ex, ey = clip[(e + 1) % 4, 0] - sx, clip[(e + 1) % 4, 1] - sy
        for k in range(count):
            side[k] = ex * (poly[k, 1] - sy) - ey * (poly[k, 0] - sx)  # >= 0: inside
        kept = 0
        for k in range(count):
            k1 = (k + 1) % count
            inside = side[k] >= 0
            if inside:
                nxt_poly[kept, 0], nxt_poly[kept, 1] = poly[k, 0], poly[k, 1]
                kept += 1
            if inside != (side[k1] >= 0):
                t = side[k] / (side[k] - side[k1])
                nxt_poly[kept, 0] = poly[k, 0] + t * (poly[k1, 0] - poly[k, 0])
                nxt_poly[kept, 1] = poly[k, 1] + t * (poly[k1, 1] - poly[k, 1])
                kept += 1
        count = kept
        for k in range(count):
            poly[k, 0], poly[k, 1] = nxt_poly[k, 0], nxt_poly[k, 1]
    if count == 0:
        return 0.0
    total = 0.0
    for k in range(count):  # in vertex order, as rotated_iou._shoelace's cumulative sum
        k1 = (k + 1) % count
        term = poly[k, 0] * poly[k1, 1] - poly[k1, 0] * poly[k, 1]
        total = term if k == 0 else total + term
    area = 0.5 * total
    smaller = min(box_a[2] * box_a[3], box_b[2] * box_b[3])
    return min(max(area, 0.0), smaller)


@numba.njit(cache=True, nogil=True)
def _area(w, l):
    return max(w, 0.0) * max(l, 0.0)


@numba.njit(cache=True, nogil=True)
def pair_iou(box_a, cos_a, sin_a, radius_a, box_b, cos_b, sin_b, radius_b, scratch):
    """`rotated_iou.bev_iou_aligned` of one pair: 0 unless both have area and their circumscribed
    circles meet (`may_touch`, with its 1e-9 slack), else the exact clipped IoU."""
    area_a, area_b = _area(box_a[2], box_a[3]), _area(box_b[2], box_b[3])
    inter = 0.0
    if area_a > 0 and area_b > 0:
        dx, dy = box_a[0] - box_b[0], box_a[1] - box_b[1]
        dist2 = dx * dx + dy * dy
        reach2 = radius_a + radius_b
        reach2 = reach2 * reach2
        reach2 = reach2 * (1 + 1e-9)
        if dist2 <= reach2:
            subject, clip, poly, nxt_poly, side = scratch
            inter = pair_intersection(box_a, cos_a, sin_a, box_b, cos_b, sin_b, subject, clip, poly, nxt_poly, side)
    union = area_a + area_b - inter
    return inter / union if union > 0 else 0.0


@numba.njit(cache=True, nogil=True)
def _scratch():
    return (np.empty((4, 2)), np.empty((4, 2)), np.empty((POLY_SLOTS, 2)), np.empty((POLY_SLOTS, 2)),
            np.empty(POLY_SLOTS))


@numba.njit(cache=True, nogil=True)
def aligned_ious(boxes_a, cos_a, sin_a, radius_a, boxes_b, cos_b, sin_b, radius_b):
    """(P,) `pair_iou` of aligned pairs: what the tests compare bitwise with bev_iou_aligned."""
    out = np.empty(len(boxes_a))
    scratch = _scratch()
    for p in range(len(boxes_a)):
        out[p] = pair_iou(boxes_a[p], cos_a[p], sin_a[p], radius_a[p],
                          boxes_b[p], cos_b[p], sin_b[p], radius_b[p], scratch)
    return out


@numba.njit(cache=True, nogil=True)
def greedy_keep(boxes, cos_yaw, sin_yaw, radius, labels, live, iou_threshold, max_output):
    """Positions kept by the plain greedy pass over boxes already in rank order: each box not yet
    suppressed is kept and suppresses every later live box of its label whose IoU with it is above
    the threshold. Boxes that are not `live` (non-finite or no area) overlap nothing. Stops after
    max_output kept boxes (< 0: no bound); the result is a prefix of the unbounded one."""
    n = len(boxes)
    suppressed = np.zeros(n, np.bool_)
    kept = np.empty(n, np.int64)
    count = 0
    scratch = _scratch()
    for i in range(n):
        if suppressed[i]:
            continue
        kept[count] = i
        count += 1
        if count == max_output:
            break
        if not live[i]:
            continue
        for j in range(i + 1, n):
            if suppressed[j] or not live[j] or labels[j] != labels[i]:
                continue
            if pair_iou(boxes[i], cos_yaw[i], sin_yaw[i], radius[i],
                        boxes[j], cos_yaw[j], sin_yaw[j], radius[j], scratch) > iou_threshold:
                suppressed[j] = True
    return kept[:count]

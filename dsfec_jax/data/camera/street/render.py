"""Exact ray casting of boxes and the ground plane, vectorised with numpy, with a per-pixel depth
buffer.

One ray per pixel centre, d = ((u - cx) / fx, (v - cy) / fy, 1) in the camera frame, so the ray
parameter t *is* the depth along the optical axis. The ground (U = 0) is hit at
t = (-h - up . o) / (up . d) where up . d < 0; with zero pitch that is t = h fy / (v - cy). Each box
is tested only on the pixels of its projected bounding rectangle: the projection of a convex box
clipped to z >= near is the hull of its projected front corners and of its edges' crossings of
the near plane, so the rectangle is exact. Inside it the slab test in the box's own frame gives
entry depth and entry face; a pixel takes the box when the entry lies nearer than the buffer.
Boxes with large rectangles are tested one by one; the many small ones (far objects, parts) are
tested together as (box, pixel) pairs, the nearest hit per pixel found with np.minimum.at, so
numpy's per-call cost is paid once per batch, not once per box (the result is the same).
Bicycles are see-through slabs but for their tyres and frame (shade.bike_parts). For every
labelled object the renderer also counts the pixels it would cover rendered alone (the union of
its parts' hits, ignoring all other geometry): the denominator of its visible fraction.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from . import shade
from .bodies import BIKE
from .camera import PinholeCamera
from .world import Look, Prims

_SIGNS = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], np.float64)
_EDGES = np.array([(i, j) for i in range(8) for j in range(i + 1, 8) if np.sum(_SIGNS[i] != _SIGNS[j]) == 1])


@dataclasses.dataclass(frozen=True)
class CameraPrims:
    """Boxes in the (left) camera frame: centre (P, 3), rot (P, 3, 3) whose columns are the box's
    along / left / up axes, half sizes (P, 3), and the attributes of Prims."""

    center: np.ndarray
    rot: np.ndarray
    half: np.ndarray
    material: np.ndarray
    color: np.ndarray
    owner: np.ndarray

    def __len__(self) -> int:
        return len(self.owner)


def to_camera(prims: Prims, cam_enu: np.ndarray, m: np.ndarray) -> CameraPrims:
    """ENU boxes -> the camera frame of rotation m (camera.camera_rotation) at cam_enu."""
    h = prims.heading
    zero = np.zeros_like(h)
    axes = np.stack([np.stack([np.sin(h), np.cos(h), zero], 1), np.stack([-np.cos(h), np.sin(h), zero], 1),
                     np.stack([zero, zero, zero + 1], 1)], 2)          # (P, 3 enu, 3 local)
    return CameraPrims((prims.center - cam_enu) @ m.T, np.einsum("ij,pjk->pik", m, axes), prims.half,
                       prims.material, prims.color, prims.owner)


def clipped_projection(center, rot, half, cam: PinholeCamera, near: float):
    """(u, v, valid), each (B, 8 + 12): the pixel positions of each box's 8 corners and of the
    points where its 12 edges cross the near plane; `valid` marks the corners in front of it and
    the edges that cross it (a box partly behind the camera projects as its visible part)."""
    corners = center[:, None, :] + np.einsum("pij,pkj->pki", rot, _SIGNS[None] * half[:, None, :])
    a, b = corners[:, _EDGES[:, 0]], corners[:, _EDGES[:, 1]]
    za, zb = a[..., 2], b[..., 2]
    cross = (za > near) != (zb > near)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, (near - za) / np.where(cross, zb - za, 1.0), 0.0)
    points = np.concatenate([corners, a + t[..., None] * (b - a)], 1)
    valid = np.concatenate([corners[..., 2] > near, cross], 1)
    z = np.where(valid, np.maximum(points[..., 2], near), 1.0)
    return cam.cx + cam.fx * points[..., 0] / z, cam.cy + cam.fy * points[..., 1] / z, valid


def box_rects(center, rot, half, cam: PinholeCamera, origin, near: float) -> np.ndarray:
    """(B, 4) int (r0, r1, c0, c1): the pixel rectangles that may see each box (empty: r1 <= r0),
    one pixel of margin."""
    if not len(center):
        return np.zeros((0, 4), np.int64)
    u, v, valid = clipped_projection(center - origin, rot, half, cam, near)
    big = 1e7
    umin = np.clip(np.where(valid, u, np.inf).min(1), -big, big)
    umax = np.clip(np.where(valid, u, -np.inf).max(1), -big, big)
    vmin = np.clip(np.where(valid, v, np.inf).min(1), -big, big)
    vmax = np.clip(np.where(valid, v, -np.inf).max(1), -big, big)
    c0 = np.clip(np.ceil(umin - 0.5) - 1, 0, cam.width)
    c1 = np.clip(np.floor(umax - 0.5) + 2, 0, cam.width)
    r0 = np.clip(np.ceil(vmin - 0.5) - 1, 0, cam.height)
    r1 = np.clip(np.floor(vmax - 0.5) + 2, 0, cam.height)
    empty = ~valid.any(1)
    r1[empty] = r0[empty]
    return np.stack([r0, r1, c0, c1], 1).astype(np.int64)


def projected_extent(center, rot, half, cam: PinholeCamera, near: float) -> np.ndarray:
    """(B, 4) float (x1, y1, x2, y2): the continuous 2D box of each box's projection (clipped to
    z >= near, *not* to the frame); NaN when it lies wholly behind the near plane."""
    out = np.full((len(center), 4), np.nan)
    if not len(center):
        return out
    u, v, valid = clipped_projection(center, rot, half, cam, near)
    uv = np.stack([u, v], -1)
    lo = np.where(valid[..., None], uv, np.inf).min(1)
    hi = np.where(valid[..., None], uv, -np.inf).max(1)
    ok = valid.any(1)
    out[ok] = np.concatenate([lo, hi], 1)[ok]
    return out


@dataclasses.dataclass
class Hits:
    depth: np.ndarray    # (H, W) float32, inf where the ray meets nothing (sky)
    prim: np.ndarray     # (H, W) int32 box index, -1 for ground and sky
    face: np.ndarray     # (H, W) uint8 entry face: 2 * axis + (normal along +axis)
    alone: dict          # owner id -> pixels it covers rendered alone (when tracked)


BATCH_AREA = 4096      # boxes with smaller rectangles are tested together, as (box, pixel) pairs
BATCH_PAIRS = 400_000  # pairs per batch


def _slab(o, d, half):
    """Entry depth, exit depth and entry face code of rays o + t d (d: 3 broadcastable arrays) in
    boxes [-half, half] (o, half: 3 scalars or (N,) arrays each)."""
    tn = tf = code = None
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for k in range(3):
            inv = np.float32(1.0) / d[k]
            t1, t2 = (-half[k] - o[k]) * inv, (half[k] - o[k]) * inv
            lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
            kcode = (d[k] < 0).astype(np.uint8) + np.uint8(2 * k)
            if tn is None:
                tn, tf, code = lo, hi, kcode
            else:
                upd = lo > tn
                tn, code, tf = np.where(upd, lo, tn), np.where(upd, kcode, code), np.minimum(tf, hi)
    return tn, tf, code


def _local_dirs(rot, du_r, dv_r):
    """The ray directions of a pixel rectangle in a box's frame, one broadcastable array per axis
    (1-D when the axis is horizontal or vertical in the image, as with zero pitch)."""
    out = []
    for k in range(3):
        a, b, c = float(rot[0, k]), float(rot[1, k]), float(rot[2, k])
        if abs(b) < 1e-12:
            out.append((a * du_r + c)[None, :])
        elif abs(a) < 1e-12:
            out.append((b * dv_r + c)[:, None])
        else:
            out.append(a * du_r[None, :] + (b * dv_r + c)[:, None])
    return out


def raycast(cp: CameraPrims, cam: PinholeCamera, origin, up, height: float, near: float,
            track_alone: bool = False) -> Hits:
    """Depth buffer of the ground and the boxes seen from `origin` (camera frame; the right camera
    of a stereo rig sits at (B, 0, 0)). up: the world's up in the camera frame; height: of the
    left camera above the ground. Boxes with large rectangles are tested one by one, the others
    together as (box, pixel) pairs; the result does not depend on the order."""
    du, dv = cam.ray_grid()
    w = cam.width
    origin = np.asarray(origin, np.float64)
    nd = float(up[0]) * du[None, :] + float(up[1]) * dv[:, None] + float(up[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = np.float32(-height - float(np.dot(up, origin))) / nd
    depth = np.where((nd < 0) & (tg > near), tg, np.float32(np.inf)).astype(np.float32)
    prim = np.full(depth.shape, -1, np.int32)
    face = np.zeros(depth.shape, np.uint8)
    rects = box_rects(cp.center, cp.rot, cp.half, cam, origin, near)
    area = np.clip(rects[:, 1] - rects[:, 0], 0, None) * np.clip(rects[:, 3] - rects[:, 2], 0, None)
    local_o = np.einsum("pji,pj->pi", cp.rot, origin - cp.center) if len(cp) else np.zeros((0, 3))
    alone = _AloneMasks(cp.owner, rects, area) if track_alone else None
    for p in np.flatnonzero((area > 0) & (area > BATCH_AREA)):
        r0, r1, c0, c1 = (int(x) for x in rects[p])
        o, half = local_o[p], cp.half[p]
        dirs = _local_dirs(cp.rot[p], du[c0:c1], dv[r0:r1])
        tn, tf, code = _slab([float(x) for x in o], dirs, [float(x) for x in half])
        hit = (tn <= tf) & (tn > near)
        if cp.material[p] == BIKE:
            hit &= shade.bike_parts(float(o[0]) + tn * dirs[0], float(o[2]) + tn * dirs[2], half)[0]
        hit = np.broadcast_to(hit, (r1 - r0, c1 - c0))
        if alone is not None and cp.owner[p] >= 0:
            alone.add_rect(p, hit)
        zb = depth[r0:r1, c0:c1]
        closer = hit & (tn < zb)
        if closer.any():
            depth[r0:r1, c0:c1] = np.where(closer, tn, zb)
            prim[r0:r1, c0:c1] = np.where(closer, np.int32(p), prim[r0:r1, c0:c1])
            face[r0:r1, c0:c1] = np.where(closer, code, face[r0:r1, c0:c1])
    small = np.flatnonzero((area > 0) & (area <= BATCH_AREA))
    flat_depth, flat_prim, flat_face = depth.reshape(-1), prim.reshape(-1), face.reshape(-1)
    hw = depth.size
    start = 0
    while start < len(small):
        stop = start + max(1, int(np.searchsorted(np.cumsum(area[small[start:]]), BATCH_PAIRS)))
        ps = small[start:stop]
        start = stop
        counts = area[ps]
        pp = np.repeat(ps, counts)
        k = np.arange(len(pp)) - np.repeat(np.cumsum(counts) - counts, counts)
        widths = np.repeat(rects[ps, 3] - rects[ps, 2], counts)
        row = np.repeat(rects[ps, 0], counts) + k // widths
        col = np.repeat(rects[ps, 2], counts) + k % widths
        rot = cp.rot[pp].astype(np.float32)
        dx, dy = du[col], dv[row]
        dirs = [rot[:, 0, j] * dx + rot[:, 1, j] * dy + rot[:, 2, j] for j in range(3)]
        o, half = local_o[pp].astype(np.float32), cp.half[pp].astype(np.float32)
        tn, tf, code = _slab(o.T, dirs, half.T)
        hit = (tn <= tf) & (tn > near)
        bike = cp.material[pp] == BIKE
        if bike.any():
            hit[bike] &= shade.bike_parts(o[bike, 0] + tn[bike] * dirs[0][bike], o[bike, 2] + tn[bike] * dirs[2][bike],
                                          half[bike])[0]
        pix = row * w + col
        if alone is not None:
            own = hit & (cp.owner[pp] >= 0)
            alone.add_pixels(pp[own], row[own], col[own])
        hit &= tn < flat_depth[pix]
        pix, tn, code, pp = pix[hit], tn[hit], code[hit], pp[hit]
        nearest = np.full(hw, np.inf, np.float32)
        np.minimum.at(nearest, pix, tn)
        win = tn == nearest[pix]
        flat_depth[pix[win]] = tn[win]
        flat_prim[pix[win]] = pp[win]
        flat_face[pix[win]] = code[win]
    return Hits(depth, prim, face, alone.counts() if alone is not None else {})


class _AloneMasks:
    """Per owner, a boolean mask over the union of its parts' rectangles (all in one flat buffer):
    the pixels the owner covers rendered alone."""

    def __init__(self, owner: np.ndarray, rects: np.ndarray, area: np.ndarray):
        used = (owner >= 0) & (area > 0)
        self.ids, inverse = np.unique(owner[used], return_inverse=True)
        self.slot = np.full(len(owner), -1, np.int64)
        self.slot[np.flatnonzero(used)] = inverse
        n = len(self.ids)
        r = rects[used]
        self.r0, self.c0 = np.full(n, 1 << 40), np.full(n, 1 << 40)
        r1, c1 = np.zeros(n, np.int64), np.zeros(n, np.int64)
        np.minimum.at(self.r0, inverse, r[:, 0])
        np.maximum.at(r1, inverse, r[:, 1])
        np.minimum.at(self.c0, inverse, r[:, 2])
        np.maximum.at(c1, inverse, r[:, 3])
        self.h, self.w = r1 - self.r0, c1 - self.c0
        self.start = np.concatenate([[0], np.cumsum(self.h * self.w)])
        self.buf = np.zeros(int(self.start[-1]), bool)
        self.rects = rects

    def view(self, k: int) -> np.ndarray:
        return self.buf[self.start[k]:self.start[k + 1]].reshape(self.h[k], self.w[k])

    def add_rect(self, p: int, hit: np.ndarray) -> None:
        k = self.slot[p]
        r0, r1, c0, c1 = (int(x) for x in self.rects[p])
        self.view(k)[r0 - self.r0[k]:r1 - self.r0[k], c0 - self.c0[k]:c1 - self.c0[k]] |= hit

    def add_pixels(self, p: np.ndarray, row: np.ndarray, col: np.ndarray) -> None:
        k = self.slot[p]
        self.buf[self.start[k] + (row - self.r0[k]) * self.w[k] + col - self.c0[k]] = True

    def counts(self) -> dict:
        return {int(i): int(np.count_nonzero(self.buf[self.start[k]:self.start[k + 1]]))
                for k, i in enumerate(self.ids)}


@functools.lru_cache(maxsize=8)
def _pixel_rays(cam: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """x / z and y / z of every pixel's ray, flattened row-major (H * W,) each."""
    du, dv = cam.ray_grid()
    return np.tile(du, cam.height), np.repeat(dv, cam.width)


def shade_view(hits: Hits, cp: CameraPrims, cam: PinholeCamera, origin, m: np.ndarray, look: Look,
               ground_rc) -> np.ndarray:
    """(H, W, 3) float32 colours in [0, 1] before exposure and noise. ground_rc(points) -> (s, d):
    road coordinates of ground points given in the camera frame (relative to the left camera);
    it also carries the road's `section` and `crossings`."""
    dx, dy = _pixel_rays(cam)
    depth, prim = hits.depth.reshape(-1), hits.prim.reshape(-1)
    rgb = np.empty((depth.size, 3), np.float32)
    up = m[:, 2]
    origin = np.asarray(origin, np.float32)
    finite = np.isfinite(depth)
    idx = np.flatnonzero(~finite)
    if len(idx):  # sky
        x, y = dx[idx], dy[idx]
        rgb[idx] = shade.sky(look, (x * up[0] + y * up[1] + up[2]) / np.sqrt(x * x + y * y + 1))
    idx = np.flatnonzero(finite & (prim < 0))
    if len(idx):  # ground
        t = depth[idx]
        pts = np.stack([origin[0] + t * dx[idx], origin[1] + t * dy[idx], origin[2] + t], 1)
        s, d = ground_rc(pts)
        light = look.ambient + look.diffuse * max(0.0, look.sun[2])
        rgb[idx] = shade.ground(look, ground_rc.section, ground_rc.crossings, s, d) * np.float32(light)
    idx = np.flatnonzero(prim >= 0)
    if len(idx):  # boxes
        p, t, f = prim[idx], depth[idx], hits.face.reshape(-1)[idx]
        rot = cp.rot.astype(np.float32)
        o = np.einsum("pji,pj->pi", cp.rot, origin - cp.center).astype(np.float32)
        x, y = dx[idx], dy[idx]
        r = rot[p]
        local = o[p] + t[:, None] * (r[:, 0, :] * x[:, None] + r[:, 1, :] * y[:, None] + r[:, 2, :])
        axis, sign = (f // 2).astype(np.int64), np.where(f % 2 == 1, 1.0, -1.0).astype(np.float32)
        half = cp.half.astype(np.float32)
        base, glass = shade.materials(cp.material[p], cp.color[p], local, half[p], axis, sign, p, look.texture_seed)
        # light per box face: ambient + Lambert towards the sun + a little sky from above
        normals = np.concatenate([-rot[:, :, :, None], rot[:, :, :, None]], 3).transpose(0, 2, 3, 1).reshape(len(cp), 6, 3)
        sun = m @ np.asarray(look.sun, np.float64)
        table = (look.ambient + look.diffuse * np.clip(normals @ sun, 0, None) + 0.08 * (normals @ up)).astype(np.float32)
        col = base * table[p, f][:, None]
        if glass.any():  # glass mirrors the sky a little, brighter towards its top
            g = np.flatnonzero(glass)
            height = np.clip((local[g, 2] + half[p[g], 2]) / (2 * half[p[g], 2]), 0, 1)
            col[g] += 0.25 * np.asarray(look.sky_horizon, np.float32) * (0.4 + 0.6 * height)[:, None]
        rgb[idx] = col
    with np.errstate(invalid="ignore"):
        haze = np.where(finite, np.exp(-depth / np.float32(look.fog_m)), np.float32(1))[:, None]
    rgb = rgb * haze + np.asarray(look.sky_horizon, np.float32) * (1 - haze)
    return rgb.reshape(cam.height, cam.width, 3)

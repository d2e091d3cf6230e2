"""Colours: the sky, the ground (road, markings, kerbs, sidewalks, verges) and the materials of the
boxes, lit by the sun (Lambert on the face normal plus ambient) and faded into haze with distance.

Every texture is a function of surface coordinates, road (s, d) on the ground and a box's own
(along, left, up) on boxes, hashed (no random stream): the left and right cameras see the same
texture at the same surface point, as a stereo pair must.
"""

from __future__ import annotations

import numpy as np

from .bodies import (BIKE, BUILDING, BUS, CABIN, CARGO, CLOTH, FOLIAGE, HEAD, PAINT, POLE, SIGN, TRUCK_CAB,
                     TRUNK, WHEEL)

GLASS = np.array([0.10, 0.13, 0.17], np.float32)
TYRE = np.array([0.06, 0.06, 0.07], np.float32)
HUB = np.array([0.55, 0.56, 0.58], np.float32)
HEADLIGHT = np.array([1.0, 0.97, 0.85], np.float32)
TAILLIGHT = np.array([0.75, 0.05, 0.05], np.float32)
ROOF = np.array([0.35, 0.34, 0.33], np.float32)
KERB = np.array([0.72, 0.72, 0.70], np.float32)


def hash01(seed: int, *coords) -> np.ndarray:
    """A uniform [0, 1) value per integer coordinate tuple (|coords| < 2**31; uint32 FNV-1a mix
    plus a finaliser)."""
    h = np.full(np.shape(coords[0]), (2166136261 ^ (seed & 0xFFFFFFFF)) & 0xFFFFFFFF, np.uint32)
    for c in coords:
        c = np.asarray(c)
        c = (c if c.dtype.kind in "iu" else c.astype(np.int64)).astype(np.int32).view(np.uint32)
        h ^= c
        h *= np.uint32(16777619)
    h ^= h >> np.uint32(15)
    h *= np.uint32(0x2C1B3C6D)
    h ^= h >> np.uint32(12)
    return h.astype(np.float32) * np.float32(2.0 ** -32)


def cell_noise(seed: int, x, y, size: float) -> np.ndarray:
    return hash01(seed, np.floor(x / size), np.floor(y / size))


def sky(look, elevation: np.ndarray) -> np.ndarray:
    """(N, 3) colours of rays with sin(elevation) `elevation`."""
    t = np.sqrt(np.clip(elevation, 0, 1))[:, None]
    return (np.asarray(look.sky_horizon, np.float32) * (1 - t) + np.asarray(look.sky_zenith, np.float32) * t)


def ground(look, section, crossings, s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, 3) colours of ground points at road coordinates (s, d), before light and haze."""
    seed = look.texture_seed
    ad = np.abs(d)
    fine = cell_noise(seed, s, d, 0.1)
    patch = cell_noise(seed + 1, s, d, 3.0)
    asphalt = np.asarray(look.asphalt, np.float32)
    out = asphalt * (0.88 + 0.18 * fine + 0.08 * (patch - 0.5))[:, None]
    bike = (ad > section.lanes_d) & (ad <= section.parking_d)
    out[bike] *= np.float32(1.06)
    mark = np.zeros(s.shape, bool)
    mark |= (ad < 0.08) & (np.mod(s, 12.0) < 5.0)                         # dashed centre line
    if section.lanes > 1:
        mark |= (np.abs(ad - section.lane_width) < 0.07) & (np.mod(s, 9.0) < 3.0)
    mark |= np.abs(ad - section.lanes_d) < 0.08                            # solid edge lines
    if section.parking_width > 0:
        mark |= (ad > section.parking_d) & (ad < section.kerb_d) & (np.mod(s, 5.5) < 0.1)
    for s_c in crossings:
        mark |= (np.abs(s - s_c) < 2.0) & (ad < section.lanes_d) & (np.mod(d, 1.0) < 0.5)
    out[mark] = np.asarray(look.marking, np.float32) * (0.92 + 0.1 * fine[mark])[:, None]
    kerb = (ad >= section.kerb_d) & (ad < section.kerb_d + 0.15)
    out[kerb] = KERB * (0.9 + 0.15 * fine[kerb])[:, None]
    walk = (ad >= section.kerb_d + 0.15) & (ad < section.sidewalk_d)
    if np.any(walk):
        sw, dw = s[walk], ad[walk] - section.kerb_d
        joint = (np.mod(sw, 0.5) < 0.03) | (np.mod(dw, 0.5) < 0.03)
        slab = cell_noise(seed + 2, sw, dw, 0.5)
        tone = (0.92 + 0.12 * slab + 0.06 * fine[walk]) * np.where(joint, 0.78, 1.0)
        out[walk] = np.asarray(look.sidewalk, np.float32) * tone[:, None].astype(np.float32)
    verge = ad >= section.sidewalk_d
    if np.any(verge):
        coarse = cell_noise(seed + 3, s[verge], d[verge], 0.7)
        out[verge] = np.asarray(look.verge, np.float32) * (0.75 + 0.35 * coarse + 0.15 * fine[verge])[:, None]
    return out


def bike_parts(along: np.ndarray, up: np.ndarray, half) -> tuple[np.ndarray, np.ndarray]:
    """(opaque, tyre) of points of a bicycle's slab (local along, up from its centre): only the
    tyres, hubs and frame tubes are solid; the rest of the slab lets rays through."""
    half = np.asarray(half, np.float32)
    z = up + half[..., 2]                 # height above the ground
    length = 2 * half[..., 0]
    r = np.minimum(0.34, 0.2 * length)
    axle = half[..., 0] - r
    tyre = np.zeros(np.broadcast(along, z).shape, bool)
    opaque = np.zeros_like(tyre)
    for x in (-axle, axle):
        rho = np.hypot(along - x, z - r)
        tyre |= np.abs(rho - r + 0.03) < 0.035
        opaque |= rho < 0.05
    top = 2 * half[..., 2]
    opaque |= (np.abs(z - 0.78 * top) < 0.035) & (np.abs(along) < 0.45 * axle)     # top tube
    opaque |= (np.abs(along + 0.1 * axle) < 0.035) & (z > r) & (z < 0.85 * top)     # seat tube
    opaque |= (np.abs(along - 0.8 * axle) < 0.035) & (z > r) & (z < top)            # fork and bars
    down = (z - r) - (along + 0.1 * axle) * (0.78 * top - r) / (0.8 * axle)          # down tube
    opaque |= (np.abs(down) < 0.05) & (along > -0.1 * axle) & (along < 0.8 * axle)
    return opaque | tyre, tyre


class _Surface:
    """Surface points of boxes of one material: local coordinates and face, in the box's frame."""

    def __init__(self, color, local, half, axis, sign, prim, seed: int):
        self.a, self.l, self.u = local[:, 0], local[:, 1], local[:, 2]
        self.half, self.axis, self.sign, self.prim, self.seed = half, axis, sign, prim, seed
        self.z = self.u + half[:, 2]           # height above the box's bottom
        self.top = 2 * half[:, 2]
        self.vertical = axis < 2
        self.hcoord = np.where(axis == 0, self.l, self.a)   # horizontal coordinate on a vertical face
        self.hhalf = np.where(axis == 0, half[:, 1], half[:, 0])
        self.front = (axis == 0) & (sign > 0)
        self.back = (axis == 0) & (sign < 0)
        self.primary, self.secondary = color[:, :3], color[:, 3:]
        self.fine = hash01(seed, prim, np.floor(self.a * 20), np.floor(self.l * 20), np.floor(self.u * 20))
        self.out = self.primary * (0.93 + 0.14 * self.fine)[:, None]
        self.glass = np.zeros(len(self.a), bool)

    def paint(self, mask, rgb):
        self.out[mask] = rgb if np.ndim(rgb) == 1 else rgb[mask]

    def speckle(self, rgb, lo: float, spread: float, noise=None):
        noise = self.fine if noise is None else noise
        return rgb * (lo + spread * noise)[:, None]


def _paint(f: _Surface):  # car body
    f.paint(f.z < 0.18 * f.top, f.out * 0.45)
    lamp = f.vertical & (np.abs(f.hcoord) > 0.6 * f.hhalf) & (f.z > 0.55 * f.top) & (f.z < 0.85 * f.top)
    f.paint(lamp & f.front, HEADLIGHT)
    f.paint(lamp & f.back, TAILLIGHT)
    f.paint((f.axis == 0) & (np.abs(f.hcoord) < 0.25) & (f.z > 0.2 * f.top) & (f.z < 0.38 * f.top),
            np.float32([0.9, 0.9, 0.88]))


def _cabin(f: _Surface):  # glass with pillars, painted roof
    f.glass |= (f.vertical & (np.abs(f.hcoord) < f.hhalf - 0.09) & (f.z > 0.06)
                & ~((f.axis == 1) & (np.abs(f.a) < 0.06)))


def _wheel(f: _Surface):
    f.paint(slice(None), TYRE)
    f.paint((f.axis == 1) & (np.hypot(f.a, f.u) < 0.55 * f.half[:, 0]), HUB)


def _bus(f: _Surface):
    z, top, half = f.z, f.top, f.half
    band = (z > 0.42 * top) & (z < 0.86 * top)
    f.glass |= (f.axis == 1) & band & (np.mod(f.a, 1.3) > 0.12)
    f.glass |= f.front & (z > 0.3 * top) & (z < 0.9 * top) & (np.abs(f.l) < half[:, 1] - 0.12)
    f.glass |= f.back & (z > 0.55 * top) & (z < 0.85 * top) & (np.abs(f.l) < half[:, 1] - 0.15)
    f.paint(f.front & (z > 0.91 * top) & (z < 0.97 * top) & (np.abs(f.l) < half[:, 1] - 0.3), np.float32([1.0, 0.6, 0.1]))
    lamp = (f.axis == 0) & (z < 0.2 * top) & (np.abs(f.l) > half[:, 1] - 0.4)
    f.paint(lamp & f.front, HEADLIGHT)
    f.paint(lamp & f.back, TAILLIGHT)


def _cargo(f: _Surface):
    f.paint((f.axis == 1) & (np.mod(f.a, 0.6) < 0.04), f.out * 0.82)
    f.paint(f.back & (np.abs(f.l) < 0.03), f.out * 0.5)


def _truck_cab(f: _Surface):
    z, top, half = f.z, f.top, f.half
    upper = (z > 0.55 * top) & (z < 0.92 * top)
    f.glass |= f.front & upper & (np.abs(f.l) < half[:, 1] - 0.1)
    f.glass |= (f.axis == 1) & upper & (f.a > -half[:, 0] + 0.25) & (f.a < half[:, 0] - 0.12)
    f.paint(z < 0.12 * top, f.out * 0.4)
    f.paint(f.front & (z > 0.15 * top) & (z < 0.28 * top) & (np.abs(f.l) > half[:, 1] - 0.4), HEADLIGHT)


def _head(f: _Surface):  # skin, hair on top and at the back
    hair = (f.axis == 2) | (f.z > 0.62 * f.top) | (f.back & (f.z > 0.3 * f.top))
    f.paint(hair, f.speckle(f.secondary, 0.9, 0.2))


def _bike(f: _Surface):
    f.paint(bike_parts(f.a, f.u, f.half)[1], TYRE)


def _building(f: _Surface):
    seed, prim, z = f.seed, f.prim, f.z
    pitch = 2.6 + 1.2 * hash01(seed + 7, prim)
    hc = np.mod(f.hcoord + f.hhalf, pitch)
    zf = np.mod(z, 3.2)
    windows = (z > 3.0) & (zf > 0.9) & (zf < 2.3) & (hc > 0.6) & (hc < pitch - 0.6)
    shop = (z > 0.4) & (z < 2.6) & (hc > 0.35) & (hc < pitch - 0.35) & (hash01(seed + 8, prim) < 0.5)
    tint = 0.7 + 0.6 * hash01(seed + 9, prim, np.floor((f.hcoord + f.hhalf) / pitch), np.floor(z / 3.2))
    f.paint(f.vertical & (windows | shop), f.secondary * tint[:, None])
    f.paint(~f.vertical, f.speckle(ROOF, 0.9, 0.2))


def _foliage(f: _Surface):
    coarse = hash01(f.seed + 5, f.prim, np.floor(f.a / 0.25), np.floor(f.l / 0.25), np.floor(f.u / 0.25))
    f.paint(slice(None), f.speckle(f.primary, 0.55, 0.8, coarse))


def _sign(f: _Surface):
    border = (np.abs(f.l) > f.half[:, 1] - 0.05) | (np.abs(f.u) > f.half[:, 2] - 0.05)
    f.paint((f.axis != 0) | border, np.float32([0.85, 0.85, 0.85]))


def _plain(f: _Surface):  # cloth, trunks, poles: a rougher texture
    f.paint(slice(None), f.speckle(f.primary, 0.85, 0.3))


_MATERIALS = {PAINT: _paint, CABIN: _cabin, WHEEL: _wheel, BUS: _bus, CARGO: _cargo, TRUCK_CAB: _truck_cab,
              HEAD: _head, BIKE: _bike, BUILDING: _building, FOLIAGE: _foliage, SIGN: _sign, CLOTH: _plain,
              TRUNK: _plain, POLE: _plain}


def materials(material, color, local, half, axis, sign, prim, seed: int):
    """(N, 3) base colours and (N,) glass flags of box surface points.

    local: (N, 3) (along, left, up) from the box centre; half: (N, 3); axis, sign: the face normal
    (local axis 0..2, +-1); prim: (N,) box index (texture seeds); color: (N, 6) primary, secondary."""
    out = np.empty((len(material), 3), np.float32)
    glass = np.zeros(len(material), bool)
    order = np.argsort(material, kind="stable")
    kinds, starts = np.unique(material[order], return_index=True)
    for kind, lo, hi in zip(kinds, starts, list(starts[1:]) + [len(order)]):
        idx = order[lo:hi]
        f = _Surface(color[idx], local[idx], half[idx], axis[idx], sign[idx], prim[idx], seed)
        _MATERIALS[int(kind)](f)
        out[idx] = np.where(f.glass[:, None], GLASS * (0.85 + 0.3 * f.fine)[:, None], f.out)
        glass[idx] = f.glass
    return out, glass

"""The road: a centre line of straight and constant-curvature segments on the ground plane (U = 0),
and its cross-section.

Road coordinates (s, d): s = arc length along the centre line, d = signed lateral offset, positive
to the left of the direction of increasing s. Traffic keeps right: lanes of the +s direction lie
at d < 0, oncoming lanes at d > 0. Headings are compass angles (rad, clockwise from north); a
positive curvature turns left (the heading decreases). A segment starting at (E0, N0) with heading
h0 and curvature k reaches, after u metres,
    h = h0 - k u,  E = E0 + u sinc(k u / 2) sin(h0 - k u / 2),  N = N0 + u sinc(k u / 2) cos(h0 - k u / 2)
(sinc x = sin x / x), exact for arcs and straights alike.

Cross-section, from the centre line outwards on each side: `lanes` lanes, a bike strip (where
cyclists ride), an optional parking strip, the kerb at |d| = kerb_d, the sidewalk, then a setback
before the building line.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class CrossSection:
    lanes: int = 1                 # per direction
    lane_width: float = 3.5
    bike_width: float = 1.4
    parking_width: float = 0.0     # 0: no parking strip
    sidewalk_width: float = 3.0
    setback: float = 2.0

    @property
    def lanes_d(self) -> float:
        """|d| of the outer edge line."""
        return self.lanes * self.lane_width

    @property
    def parking_d(self) -> float:
        """|d| where the parking strip begins (the bike strip's outer edge)."""
        return self.lanes_d + self.bike_width

    @property
    def kerb_d(self) -> float:
        return self.parking_d + self.parking_width

    @property
    def sidewalk_d(self) -> float:
        """|d| of the sidewalk's outer edge."""
        return self.kerb_d + self.sidewalk_width

    @property
    def building_d(self) -> float:
        return self.sidewalk_d + self.setback

    def lane_center(self, lane: int, direction: int) -> float:
        """d of lane `lane` (0 = next to the centre line) of direction +1 (d < 0) or -1 (d > 0)."""
        return -direction * (lane + 0.5) * self.lane_width


def _sinc(x):
    return np.sinc(np.asarray(x) / np.pi)


class Road:
    """Segments (length_m, curvature_per_m) from a start point and heading (E, N in metres)."""

    def __init__(self, start_en, heading: float, lengths, curvatures, section: CrossSection = CrossSection()):
        self.lengths = np.asarray(lengths, np.float64)
        self.curvatures = np.asarray(curvatures, np.float64)
        if self.lengths.ndim != 1 or self.lengths.shape != self.curvatures.shape or np.any(self.lengths <= 0):
            raise ValueError("Road: lengths and curvatures must be 1-D of one length, lengths > 0")
        if np.any(np.abs(self.curvatures * self.lengths) > math.pi):
            raise ValueError("Road: a segment may turn by at most pi")
        self.section = section
        self.s0 = np.concatenate([[0.0], np.cumsum(self.lengths)[:-1]])
        n = len(self.lengths)
        self.h0, self.e0, self.n0 = np.zeros(n), np.zeros(n), np.zeros(n)
        e, nn, h = float(start_en[0]), float(start_en[1]), float(heading)
        for i in range(n):
            self.e0[i], self.n0[i], self.h0[i] = e, nn, h
            e, nn, h = (float(x) for x in self._advance(i, self.lengths[i]))

    @classmethod
    def straight(cls, length: float = 1000.0, start_en=(0.0, 0.0), heading: float = 0.0,
                 section: CrossSection = CrossSection()) -> "Road":
        return cls(start_en, heading, [length], [0.0], section)

    @property
    def length(self) -> float:
        return float(self.s0[-1] + self.lengths[-1])

    def _advance(self, i, u):
        k, h0 = self.curvatures[i], self.h0[i]
        half = k * u / 2
        step = u * _sinc(half)
        return self.e0[i] + step * np.sin(h0 - half), self.n0[i] + step * np.cos(h0 - half), h0 - k * u

    def segment(self, s) -> np.ndarray:
        return np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)

    def pose(self, s):
        """(E, N, heading) of the centre line at arc length s (scalars or arrays; beyond the ends the
        first / last segment continues)."""
        s = np.asarray(s, np.float64)
        i = self.segment(s)
        e, n, h = self._advance(i, s - self.s0[i])
        return e, n, h

    def curvature(self, s):
        return self.curvatures[self.segment(np.asarray(s, np.float64))]

    def to_world(self, s, d):
        """(E, N, heading of the centre line) of road coordinates (s, d)."""
        e, n, h = self.pose(s)
        d = np.asarray(d, np.float64)
        # left = (-cos h, sin h)
        return e - d * np.cos(h), n + d * np.sin(h), h

    def segments_between(self, s_lo: float, s_hi: float) -> np.ndarray:
        ends = self.s0 + self.lengths
        return np.flatnonzero((ends >= s_lo) & (self.s0 <= s_hi))

    def locate(self, e, n, segments=None, origin=(0.0, 0.0)):
        """Road coordinates (s, d) of ground points (e, n) given relative to `origin` (float32 arrays
        are fine: only differences to nearby segment points are formed). Each point goes to the
        segment whose (clamped) nearest point is closest."""
        e = np.asarray(e, np.float32)
        n = np.asarray(n, np.float32)
        best = np.full(e.shape, np.inf, np.float32)
        s_out = np.zeros(e.shape, np.float32)
        d_out = np.zeros(e.shape, np.float32)
        for i in (range(len(self.s0)) if segments is None else segments):
            k, h0, length = self.curvatures[i], self.h0[i], self.lengths[i]
            pe, pn = self.e0[i] - origin[0], self.n0[i] - origin[1]
            if abs(k) < 1e-9:
                fe, fn = math.sin(h0), math.cos(h0)
                re, rn = e - np.float32(pe), n - np.float32(pn)
                along = re * np.float32(fe) + rn * np.float32(fn)
                lateral = rn * np.float32(fe) - re * np.float32(fn)  # (re, rn) . left
                u = np.clip(along, 0, length)
                dist = (along - u) ** 2 + lateral ** 2
            else:
                r = 1.0 / abs(k)
                ce, cn = pe - math.cos(h0) / k, pn + math.sin(h0) / k  # centre = start + left / k
                re, rn = e - np.float32(ce), n - np.float32(cn)
                rho = np.sqrt(re * re + rn * rn)
                a0 = math.atan2(pn - cn, pe - ce)
                sweep = (np.arctan2(rn, re) - np.float32(a0) + np.float32(math.pi)) % np.float32(2 * math.pi) - np.float32(math.pi)
                along = sweep * np.float32(math.copysign(r, k))  # counter-clockwise for left turns
                u = np.clip(along, 0, length)
                lateral = np.float32(math.copysign(1.0, k)) * (np.float32(r) - rho)
                dist = np.where(along == u, (rho - np.float32(r)) ** 2, np.float32(np.inf))
                ends = (along != u)
                if np.any(ends):  # beyond the arc: distance to its end point
                    ee, en, _ = self._advance(i, u[ends].astype(np.float64))
                    dist[ends] = (e[ends] - (ee - origin[0])) ** 2 + (n[ends] - (en - origin[1])) ** 2
            closer = dist < best
            best = np.where(closer, dist, best)
            s_out = np.where(closer, np.float32(self.s0[i]) + u, s_out)
            d_out = np.where(closer, lateral, d_out)
        return s_out, d_out

"""The road around the ego: lanes, parking rows, bike lanes, sidewalks, and the walls beside them.

Everything is a straight line in the current ego frame (x forward, y left, the sensor at the
origin): `rows` are where actors stand or drive, `walls` are where static structures are
(guard rails, building fronts, pole lines). Each line has an origin, a direction angle, an
extent [s_lo, s_hi] along it and one gap [ex_lo, ex_hi] (where a cross road cuts it).
Right-hand traffic: forward lanes on the right, oncoming lanes on the left (+y).
"""

from __future__ import annotations

import dataclasses

import numpy as np

ROW_KINDS = ("lane", "parking", "bike", "sidewalk", "crosswalk")
WALL_KINDS = ("rail", "building", "pole")
LANE_W = 3.5
NO_GAP = (np.inf, np.inf)


@dataclasses.dataclass(frozen=True)
class Lines:
    origin: np.ndarray  # (L, 2)
    theta: np.ndarray   # (L,) direction of s
    s_lo: np.ndarray    # (L,)
    s_hi: np.ndarray
    ex_lo: np.ndarray   # (L,) gap start along s (inf: none)
    ex_hi: np.ndarray
    kind: np.ndarray    # (L,) int index into ROW_KINDS or WALL_KINDS
    travel: np.ndarray  # (L,) +1 along s, -1 against, 0 either way per actor

    def __len__(self):
        return len(self.kind)

    def direction(self) -> np.ndarray:
        return np.stack([np.cos(self.theta), np.sin(self.theta)], -1)


@dataclasses.dataclass(frozen=True)
class Layout:
    highway: bool
    psi: float      # road heading in the ego frame (the ego is not perfectly lane-aligned)
    rows: Lines
    walls: Lines


class _LineList:
    """Collects lines given in road coordinates (s along the road, l to its left)."""

    def __init__(self, psi: float):
        self.e = np.array([np.cos(psi), np.sin(psi)])
        self.n = np.array([-np.sin(psi), np.cos(psi)])
        self.psi = psi
        self.items = []

    def along(self, l, kind, s_span, gap=NO_GAP, travel=0):
        """A line parallel to the main road at lateral offset l."""
        self.items.append((l * self.n, self.psi, *s_span, *gap, kind, travel))

    def across(self, s, l_mid, kind, t_span, gap=NO_GAP, travel=0):
        """A line of the cross road at main-road position s, running to the left (+l)."""
        self.items.append((s * self.e + l_mid * self.n, self.psi + np.pi / 2, *t_span, *gap, kind, travel))

    def build(self) -> Lines:
        if not self.items:
            z = np.zeros(0)
            return Lines(np.zeros((0, 2)), z, z, z, z, z, z.astype(int), z.astype(int))
        origin, theta, s_lo, s_hi, ex_lo, ex_hi, kind, travel = zip(*self.items)
        return Lines(np.array(origin), np.array(theta), np.array(s_lo), np.array(s_hi), np.array(ex_lo),
                     np.array(ex_hi), np.array(kind, int), np.array(travel, int))


def sample_layout(rng: np.random.Generator, s_span=(-15.0, 100.0), highway_prob: float = 0.35) -> Layout:
    highway = bool(rng.random() < highway_prob)  # drawn even at 0 or 1: the stream stays aligned
    psi = float(rng.normal(0.0, np.deg2rad(1.5)))
    rows, walls = _LineList(psi), _LineList(psi)
    n_fwd = int(rng.integers(2, 4) if highway else rng.integers(1, 3))
    n_onc = n_fwd if highway else int(rng.integers(1, 3))
    ego_lane = int(rng.integers(n_fwd))  # 0 = leftmost forward lane
    shift = float(rng.normal(0.0, 0.3))  # the ego is rarely on the lane centre
    fwd = [(ego_lane - i) * LANE_W - shift for i in range(n_fwd)]
    median = float(rng.uniform(2.0, 4.0)) if highway else 0.0
    onc = [fwd[0] + LANE_W + median + j * LANE_W for j in range(n_onc)]
    right, left = fwd[-1] - LANE_W / 2, onc[-1] + LANE_W / 2
    cross, stop = NO_GAP, NO_GAP
    if highway:
        _highway_sides(rng, walls, right, left, fwd[0] + LANE_W / 2 + median / 2, s_span)
    else:
        cross, stop = _cross_road(rng, rows, walls, right, left)
    for l in fwd:  # traffic stops short of a crosswalk, so no car stands on it
        rows.along(l, 0, s_span, stop, travel=+1)
    for l in onc:
        rows.along(l, 0, s_span, stop, travel=-1)
    if highway:
        return Layout(True, psi, rows.build(), walls.build())
    for side, edge in ((-1, right), (+1, left)):
        _urban_side(rng, rows, walls, side, edge, s_span, cross)
    return Layout(False, psi, rows.build(), walls.build())


def _highway_sides(rng, walls, right, left, median_l, s_span):
    """Guard rails at both shoulders and in the median; sometimes lighting poles."""
    for side, edge in ((-1, right), (+1, left)):
        rail = edge + side * rng.uniform(1.0, 3.0)
        walls.along(rail, 0, s_span)
        if rng.random() < 0.5:
            walls.along(rail + side * 0.5, 2, s_span)
    walls.along(median_l, 0, s_span)


def _cross_road(rng, rows, walls, right, left):
    """An intersection ahead (sometimes): one lane each way, sidewalks, buildings.

    Returns the stretch of the main road it and its crosswalk occupy (kerbside lines skip it) and
    the crosswalk's stretch (lanes stop short of it), or NO_GAP."""
    if rng.random() >= 0.4:
        return NO_GAP, NO_GAP
    s_c = float(rng.uniform(20.0, 60.0))
    half = LANE_W + 3.0  # lanes plus sidewalks, the stretch other lines skip
    l_mid, t_span = (left + right) / 2, (-55.0, 55.0)
    inner = ((right - 6.0) - l_mid, (left + 6.0) - l_mid)  # the main road and its sidewalks
    rows.across(s_c - LANE_W / 2, l_mid, 0, t_span, inner, travel=-1)  # right-hand traffic here too
    rows.across(s_c + LANE_W / 2, l_mid, 0, t_span, inner, travel=+1)
    for side in (-1, +1):
        rows.across(s_c + side * (LANE_W + 1.5), l_mid, 3, t_span, inner)
        walls.across(s_c + side * (LANE_W + 3.0 + rng.uniform(0.0, 3.0)), l_mid, 1, t_span, inner)
    if rng.random() >= 0.6:
        return (s_c - half, s_c + half), NO_GAP
    s_cw = s_c - half - 1.5  # a crosswalk over the main road, pedestrians walking across it
    rows.across(s_cw, l_mid, 4, (right - l_mid - 2.0, left - l_mid + 2.0))
    return (s_cw - 1.5, s_c + half), (s_cw - 1.5, s_cw + 1.5)


def _urban_side(rng, rows, walls, side, edge, s_span, gap):
    """From the kerb outward: bike lane, parking row, sidewalk with poles, building fronts."""
    l = edge
    if rng.random() < 0.5:
        rows.along(l + side * 0.75, 2, s_span, gap, travel=+1 if side < 0 else -1)
        l += side * 1.5
    if rng.random() < 0.7:
        rows.along(l + side * 1.1, 1, s_span, gap, travel=+1 if side < 0 else -1)
        l += side * 2.2
    rows.along(l + side * 1.5, 3, s_span, gap)
    walls.along(l + side * 0.4, 2, s_span, gap)
    walls.along(l + side * (3.0 + rng.uniform(0.0, 4.0)), 1, s_span, gap)

"""A world: the road, the road users moving along it, static clutter, the light, and the ego's plan.

Everything lives in one ENU frame (geo.py); the ground is the plane U = 0. Road users move at a
constant speed in road coordinates, s(t) = s + vs t, d(t) = d + vd t, so a world can be rendered
at any time: a drive renders one world at the camera's frame times, an independent frame renders
a world once at t = 0. Streams never collide: the vehicles of one lane share the lane's speed (the
ego's lane moves with the ego), cyclists ride the bike strips, pedestrians walk the sidewalks in
two streams (inner +s, outer -s) of one speed each, parked cars and standing pedestrians stand
still. Crossing pedestrians appear only in independent frames (they would meet the traffic over
a drive); the vehicles that would overlap their crosswalk are left out.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .bodies import BUILDING, FOLIAGE, POLE, SIGN, TRUNK, parts, sample_colors
from .config import StreetConfig
from .road import CrossSection, Road


@dataclasses.dataclass(frozen=True)
class Prims:
    """Boxes in ENU: centre (P, 3), compass heading of their `along` axis (P,), half sizes (along,
    left, up) (P, 3), material (P,), colours (P, 6) (primary, secondary rgb in [0, 1]), owner (P,):
    the actor id, or -1 for clutter."""

    center: np.ndarray
    heading: np.ndarray
    half: np.ndarray
    material: np.ndarray
    color: np.ndarray
    owner: np.ndarray

    def __len__(self) -> int:
        return len(self.heading)

    @classmethod
    def empty(cls) -> "Prims":
        return cls(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int16),
                   np.zeros((0, 6), np.float32), np.zeros(0, np.int32))

    @classmethod
    def from_list(cls, rows: list[tuple]) -> "Prims":
        """rows of (centre, heading, half, material, colour (6,), owner)."""
        if not rows:
            return cls.empty()
        c, h, hf, m, col, o = zip(*rows)
        return cls(np.array(c, np.float64), np.array(h, np.float64), np.array(hf, np.float64),
                   np.array(m, np.int16), np.array(col, np.float32), np.array(o, np.int32))

    @classmethod
    def concat(cls, parts_: list["Prims"]) -> "Prims":
        parts_ = [p for p in parts_ if len(p)] or [cls.empty()]
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts_]) for f in dataclasses.fields(cls)))

    def select(self, keep) -> "Prims":
        return Prims(*(getattr(self, f.name)[keep] for f in dataclasses.fields(self)))


@dataclasses.dataclass(frozen=True)
class Actor:
    """A labelled road user. yaw: its heading relative to the road's +s direction (0 along, pi
    against, -pi/2 facing +d, i.e. left); size (width, length, height)."""

    id: int
    name: str
    s: float
    d: float
    vs: float = 0.0
    vd: float = 0.0
    yaw: float = 0.0
    size: tuple[float, float, float] = (1.8, 4.5, 1.5)
    colors: tuple = ((0.6, 0.1, 0.1),)

    def at(self, t: float) -> tuple[float, float]:
        return self.s + self.vs * t, self.d + self.vd * t


@dataclasses.dataclass(frozen=True)
class Look:
    """Light and surfaces of one world (colours rgb in [0, 1])."""

    sun: tuple[float, float, float] = (0.3, -0.5, 0.81)  # unit ENU vector towards the sun
    ambient: float = 0.55
    diffuse: float = 0.5
    sky_zenith: tuple[float, float, float] = (0.30, 0.50, 0.85)
    sky_horizon: tuple[float, float, float] = (0.78, 0.85, 0.93)
    fog_m: float = 600.0
    asphalt: tuple[float, float, float] = (0.33, 0.33, 0.34)
    sidewalk: tuple[float, float, float] = (0.63, 0.62, 0.60)
    verge: tuple[float, float, float] = (0.33, 0.45, 0.22)
    marking: tuple[float, float, float] = (0.9, 0.9, 0.88)
    exposure: float = 1.0
    noise_sd: float = 0.0
    texture_seed: int = 0


@dataclasses.dataclass(frozen=True)
class EgoPlan:
    s: float            # at t = 0
    d: float            # lateral offset of the camera (its lane centre)
    speed: float = 0.0  # ds/dt


@dataclasses.dataclass(frozen=True)
class World:
    road: Road
    actors: tuple[Actor, ...] = ()
    static: Prims = dataclasses.field(default_factory=Prims.empty)
    look: Look = Look()
    ego: EgoPlan = EgoPlan(50.0, -1.75)
    crossings: tuple[float, ...] = ()   # s of zebra crossings

    def ego_ground(self, t: float) -> tuple[float, float, float, float]:
        """(E, N, heading, ground speed) of the point on the road under the camera at time t."""
        s = self.ego.s + self.ego.speed * t
        e, n, h = self.road.to_world(s, self.ego.d)
        speed = self.ego.speed * (1 - float(self.road.curvature(s)) * self.ego.d)  # a parallel path
        return float(e), float(n), float(h), speed

    def actor_states(self, t: float) -> dict[str, np.ndarray]:
        """Per actor: id, name, centre of its 3D box (E, N, U = height / 2), compass heading, size."""
        if not self.actors:
            return dict(id=np.zeros(0, np.int32), name=np.zeros(0, "<U16"), center=np.zeros((0, 3)),
                        heading=np.zeros(0), size=np.zeros((0, 3)))
        sd = np.array([a.at(t) for a in self.actors])
        e, n, h = self.road.to_world(sd[:, 0], sd[:, 1])
        size = np.array([a.size for a in self.actors], np.float64)
        return dict(id=np.array([a.id for a in self.actors], np.int32),
                    name=np.array([a.name for a in self.actors], "<U16"),
                    center=np.stack([e, n, size[:, 2] / 2], 1),
                    heading=np.mod(h + np.array([a.yaw for a in self.actors]), 2 * math.pi), size=size)

    def actor_prims(self, t: float, keep=None) -> Prims:
        """The parts of the actors (all, or those where `keep` is True) at time t, in ENU."""
        states = self.actor_states(t)
        rows = []
        for i, a in enumerate(self.actors):
            if keep is not None and not keep[i]:
                continue
            h = states["heading"][i]
            along = np.array([math.sin(h), math.cos(h), 0.0])
            left = np.array([-math.cos(h), math.sin(h), 0.0])
            base = np.array([states["center"][i, 0], states["center"][i, 1], 0.0])
            for (ca, cl, cu), half, material, color in parts(a.name, a.size, a.colors):
                rows.append((base + ca * along + cl * left + np.array([0, 0, cu]), h, half, material, color, a.id))
        return Prims.from_list(rows)


# ------------------------------------------------------------------------------ sampling


FACADES = np.array([[0.82, 0.76, 0.62], [0.60, 0.60, 0.60], [0.90, 0.90, 0.88], [0.60, 0.30, 0.22],
                    [0.45, 0.33, 0.25], [0.90, 0.82, 0.55], [0.60, 0.70, 0.80], [0.30, 0.30, 0.32],
                    [0.75, 0.55, 0.45]], np.float32)
SIGNS = np.array([[0.1, 0.3, 0.75], [0.8, 0.1, 0.1], [0.92, 0.92, 0.9], [0.95, 0.8, 0.1]], np.float32)


def split_area(cfg: StreetConfig, split_id: int) -> tuple[float, float]:
    """ENU centre of a split's square (train, val, test side by side along east, 1.5 areas apart)."""
    return (split_id - 1) * 1.5 * cfg.split_area_km * 1000.0, 0.0


def sample_section(rng: np.random.Generator, cfg: StreetConfig) -> CrossSection:
    return CrossSection(lanes=int(rng.choice(cfg.lanes_per_direction)), lane_width=rng.uniform(*cfg.lane_width_m),
                        bike_width=rng.uniform(*cfg.bike_strip_m),
                        parking_width=2.2 if rng.random() < cfg.parking_prob else 0.0,
                        sidewalk_width=rng.uniform(*cfg.sidewalk_m), setback=rng.uniform(*cfg.setback_m))


def sample_road(rng: np.random.Generator, cfg: StreetConfig, section: CrossSection, start_en, heading: float,
                first_straight: float, length: float) -> Road:
    """A straight of `first_straight` m, then curves and straights alternating, >= `length` m."""
    lengths, curvatures = [first_straight], [0.0]
    while sum(lengths) < length:
        radius = rng.uniform(*cfg.curve_radius_m)
        angle = math.radians(rng.uniform(*cfg.curve_angle_deg))
        lengths += [radius * angle, rng.uniform(*cfg.straight_m)]
        curvatures += [rng.choice([-1.0, 1.0]) / radius, 0.0]
    return Road(start_en, heading, lengths, curvatures, section)


def sample_look(rng: np.random.Generator, cfg: StreetConfig) -> Look:
    el, az = math.radians(rng.uniform(15, 65)), rng.uniform(0, 2 * math.pi)
    sun = (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))
    grey = float(rng.uniform(0.25, 0.42))
    if rng.random() < 0.3:  # overcast
        k = rng.uniform(0.85, 1.1)
        zenith, horizon, ambient, diffuse = (0.62 * k, 0.65 * k, 0.70 * k), (0.80, 0.82, 0.85), 0.78, 0.22
    else:
        zenith = tuple(np.clip(np.array([0.25, 0.45, 0.82]) + 0.05 * rng.standard_normal(3), 0, 1))
        horizon, ambient, diffuse = (0.75, 0.83, 0.92), rng.uniform(0.45, 0.6), rng.uniform(0.45, 0.65)
    verge = (0.30, 0.44, 0.20) if rng.random() < 0.6 else (0.52, 0.50, 0.47)
    return Look(sun=sun, ambient=float(ambient), diffuse=float(diffuse), sky_zenith=tuple(map(float, zenith)),
                sky_horizon=horizon, fog_m=float(rng.uniform(250, 900)),
                asphalt=(grey, grey, grey * rng.uniform(1.0, 1.06)),
                sidewalk=tuple(float(x) for x in rng.uniform(0.5, 0.72) * np.array([1, 0.98, rng.uniform(0.9, 1.0)])),
                verge=verge, marking=tuple(float(x) for x in np.array([0.9, 0.9, 0.88]) * rng.uniform(0.8, 1.0)),
                exposure=float(rng.uniform(0.85, 1.15)), noise_sd=float(rng.uniform(*cfg.noise_sd)),
                texture_seed=int(rng.integers(2**31)))


def sample_static(rng: np.random.Generator, road: Road, s_lo: float, s_hi: float) -> Prims:
    """Buildings behind the setback, trees and street lights in the sidewalk's furniture zone (its
    first 0.9 m from the kerb), some traffic signs."""
    sec, rows = road.section, []

    def put(s, d, up, half, material, color, yaw=0.0):
        e, n, h = road.to_world(s, d)
        rows.append(((float(e), float(n), up), float(h) + yaw, half, material, color, -1))

    for side in (1.0, -1.0):  # +1: left of +s
        s = s_lo + rng.uniform(0, 10)
        while s < s_hi:
            frontage = rng.uniform(8, 28)
            if rng.random() > 0.15:
                depth, height = rng.uniform(8, 18), rng.uniform(6, 28) if rng.random() > 0.15 else rng.uniform(28, 45)
                mid = s + frontage / 2
                k = max(abs(float(road.curvature(x))) for x in (s, mid, s + frontage))
                d = side * (sec.building_d + frontage ** 2 * k / 8 + 0.3 + depth / 2)
                facade = np.clip(FACADES[rng.integers(len(FACADES))] * rng.uniform(0.85, 1.1), 0, 1)
                window = np.clip(np.array([0.18, 0.22, 0.28]) * rng.uniform(0.6, 1.6), 0, 1)
                put(mid, d, height / 2, (frontage / 2, depth / 2, height / 2), BUILDING, np.concatenate([facade, window]))
            s += frontage + rng.uniform(0, 4)
        furniture = side * (sec.kerb_d + 0.45)
        if rng.random() < 0.6:  # a tree-lined street
            s = s_lo + rng.uniform(0, 12)
            while s < s_hi:
                trunk = rng.uniform(2.3, 3.5)  # crowns start >= 2 m: above every pedestrian
                put(s, furniture, trunk / 2, (0.13, 0.13, trunk / 2), TRUNK, np.tile([0.32, 0.24, 0.16], 2))
                r, top = rng.uniform(1.0, 2.2), rng.uniform(2.0, 4.0)
                leaf = np.clip(np.array([0.22, 0.38, 0.14]) * rng.uniform(0.7, 1.3), 0, 1)
                put(s, furniture + side * (r - 0.6), trunk - 0.3 + top / 2, (r, r, top / 2), FOLIAGE, np.tile(leaf, 2))
                s += rng.uniform(8, 20)
        s = s_lo + rng.uniform(0, 30)
        while s < s_hi:
            height = rng.uniform(6, 8)
            put(s, furniture, height / 2, (0.08, 0.08, height / 2), POLE, np.tile([0.45, 0.46, 0.48], 2))
            put(s, furniture - side * 0.8, height - 0.1, (0.08, 0.8, 0.06), POLE, np.tile([0.45, 0.46, 0.48], 2))
            if rng.random() < 0.3:
                s_sign = s + rng.uniform(3, 10)
                put(s_sign, furniture, 1.2, (0.04, 0.04, 1.2), POLE, np.tile([0.5, 0.5, 0.5], 2))
                put(s_sign, furniture, 2.7, (0.02, 0.35, 0.35), SIGN, np.tile(SIGNS[rng.integers(len(SIGNS))], 2))
            s += rng.uniform(25, 45)
    return Prims.from_list(rows)


def _size(rng, cfg: StreetConfig, name: str) -> tuple[float, float, float]:
    spec = cfg.spec(name)
    z = np.clip(rng.standard_normal(3), -2, 2)
    return tuple(float(m + sd * x) for m, sd, x in zip(spec.size_m, spec.size_sd_m, z))


class _Ids:
    def __init__(self):
        self.n = 0

    def __call__(self) -> int:
        self.n += 1
        return self.n - 1


def _stream(rng, cfg, ids, names, p, s_lo, s_hi, d, jitter, vs, yaw, gap_m, min_gap) -> list[Actor]:
    """Objects one after another along s in [s_lo, s_hi]: class ~ p over `names`, free gaps
    min_gap + Exp(gap_m)."""
    out, s = [], s_lo + rng.uniform(0, gap_m)
    while True:
        name = names[rng.choice(len(names), p=p)]
        size = _size(rng, cfg, name)
        if s + size[1] > s_hi:
            return out
        out.append(Actor(ids(), name, s + size[1] / 2, d + jitter * float(rng.standard_normal()), vs, 0.0, yaw,
                         size, sample_colors(rng, name)))
        s += size[1] + min_gap + rng.exponential(gap_m)


def sample_actors(rng: np.random.Generator, cfg: StreetConfig, road: Road, ego: EgoPlan, duration: float,
                  snapshot: bool) -> tuple[list[Actor], list[float]]:
    """Road users that may come into view during [0, duration] (list), and crosswalk positions."""
    sec, ids, actors = road.section, _Ids(), []
    veh_p = np.asarray(cfg.vehicle_mix) / sum(cfg.vehicle_mix)

    def window(v_along):
        """[s_lo, s_hi] at t = 0 of objects moving at v_along (m/s along +s) that reach the view."""
        r = v_along - ego.speed
        return ego.s - 8 - max(r * duration, 0.0), ego.s + cfg.view_m - min(r * duration, 0.0)

    for direction in (1, -1):  # +1: the ego's direction (d < 0)
        yaw = 0.0 if direction == 1 else math.pi
        for lane in range(sec.lanes):
            d = sec.lane_center(lane, direction)
            ego_lane = direction == 1 and abs(d - ego.d) < 1e-6
            v = ego.speed if ego_lane else direction * rng.uniform(*cfg.spec("car").speed_mps)
            lo, hi = window(v)
            if ego_lane:
                lo = ego.s + rng.uniform(4.0, 20.0)
            actors += _stream(rng, cfg, ids, ("car", "truck", "bus"), veh_p, lo, hi, d, 0.15, v, yaw, cfg.lane_gap_m, 2.0)
        v = direction * rng.uniform(*cfg.spec("cyclist").speed_mps)
        actors += _stream(rng, cfg, ids, ("cyclist",), None, *window(v), -direction * (sec.lanes_d + sec.bike_width / 2),
                          0.1, v, yaw, cfg.cyclist_gap_m, 3.0)
        if sec.parking_width > 0:
            actors += _stream(rng, cfg, ids, ("car",), None, *window(0.0), -direction * (sec.parking_d + sec.parking_width / 2),
                              0.1, 0.0, yaw, cfg.parked_gap_m, 0.8)
        # sidewalk: the furniture zone, then an inner (+s) and an outer (-s) stream
        inner, outer = sec.kerb_d + 0.9, sec.sidewalk_d - 0.25
        mid = (inner + outer) / 2
        for sign, (a, b) in ((1, (inner, mid)), (-1, (mid, outer))):
            v = sign * rng.uniform(*cfg.spec("pedestrian").speed_mps)
            actors += _stream(rng, cfg, ids, ("pedestrian",), None, *window(v), -direction * (a + b) / 2,
                              max(0.0, (b - a) / 2 - 0.3) / 2, v, 0.0 if sign == 1 else math.pi,
                              cfg.pedestrian_gap_m, 0.6)
        if sec.setback >= 1.2:  # standing in front of the buildings, facing the street
            actors += _stream(rng, cfg, ids, ("pedestrian",), None, *window(0.0),
                              -direction * (sec.sidewalk_d + sec.setback / 2), 0.15, 0.0,
                              -direction * math.pi / 2, 3 * cfg.pedestrian_gap_m, 1.0)
    crossings = []
    if snapshot and rng.random() < cfg.crossing_prob:
        s_c = ego.s + rng.uniform(10.0, 40.0)
        crossings.append(s_c)
        on_road = [a for a in actors if abs(a.d) < sec.parking_d and abs(a.s - s_c) < 3.0 + a.size[1] / 2]
        actors = [a for a in actors if not any(a is b for b in on_road)]
        ds = np.sort(rng.uniform(-sec.lanes_d + 0.4, sec.lanes_d - 0.4, rng.integers(1, 5)))
        for d in ds[np.concatenate([[True], np.diff(ds) > 0.8])]:
            size = _size(rng, cfg, "pedestrian")
            actors.append(Actor(ids(), "pedestrian", s_c + rng.uniform(-1.2, 1.2), float(d), 0.0, 0.0,
                                rng.choice([-1.0, 1.0]) * math.pi / 2, size, sample_colors(rng, "pedestrian")))
    return actors, crossings


def sample_world(rng: np.random.Generator, cfg: StreetConfig, split_id: int, duration: float = 0.0,
                 snapshot: bool = True) -> World:
    """A world for a drive of `duration` seconds (0: one frame at t = 0). Draw order: start and
    heading, cross-section, ego, road, look, clutter, road users."""
    centre = split_area(cfg, split_id)
    half = cfg.split_area_km * 500.0
    start = (centre[0] + rng.uniform(-half, half), centre[1] + rng.uniform(-half, half))
    heading = rng.uniform(0, 2 * math.pi)
    section = sample_section(rng, cfg)
    lane = int(rng.integers(section.lanes))
    speed = rng.uniform(*cfg.ego_speed_mps)
    s_ego = 80.0
    ego = EgoPlan(s_ego, section.lane_center(lane, 1), speed)
    s_end = s_ego + speed * duration
    fast = max(cfg.spec(n).speed_mps[1] for n in cfg.classes) + speed
    road = sample_road(rng, cfg, section, start, heading, s_ego + rng.uniform(10, 60),
                       s_end + cfg.draw_distance_m + fast * duration + 100)
    look = sample_look(rng, cfg)
    static = sample_static(rng, road, s_ego - 30, s_end + cfg.draw_distance_m)
    actors, crossings = sample_actors(rng, cfg, road, ego, duration, snapshot)
    return World(road, tuple(actors), static, look, ego, tuple(crossings))

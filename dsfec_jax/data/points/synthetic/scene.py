"""A scene: actors placed on the layout's rows, moving at constant velocity, and the ego's motion.

All positions are in the current ego frame at t = 0 (x forward, y left, sensor at the origin,
ground at z = -sensor_height). Past sweeps happen at t < 0: actors were at center + velocity * t,
the ego at `EgoMotion.pose(t)`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .config import CLASS_PROFILES, CLASSES, SyntheticConfig
from .layout import ROW_KINDS, Layout, sample_layout

SLOTS = 24  # actor slots per row; rows are filled front to back until they run out of road

# Per row kind: class mix (car, truck, pedestrian, bicycle), mean gap (m), occupancy,
# heading noise (deg) and lateral jitter (m, standard deviation or half-width for sidewalks).
_ROW_TABLE = {
    "lane": ((0.86, 0.10, 0.0, 0.04), 20.0, 1.0, 1.5, 0.25),
    "parking": ((0.90, 0.10, 0.0, 0.0), 2.0, 0.7, 3.0, 0.15),
    "bike": ((0.0, 0.0, 0.0, 1.0), 40.0, 1.0, 4.0, 0.2),
    "sidewalk": ((0.0, 0.0, 0.92, 0.08), 10.0, 1.0, 15.0, 1.2),
    "crosswalk": ((0.0, 0.0, 1.0, 0.0), 5.0, 0.5, 10.0, 0.8),
}
_HIGHWAY_LANE = ((0.75, 0.25, 0.0, 0.0), 35.0)
# View-of-Delft's old town (assumed numbers; VoD: pedestrians and cyclists dominate, cars are
# common, trucks rare; its 3 example frames hold 16 pedestrians, 8 cyclists, 15 parked bicycles
# and 1 car): cyclists share the lanes, bicycles stand parked along the kerb, busy bike lanes
# and crowded sidewalks, and no highway.
_VOD_ROWS = {
    "lane": ((0.55, 0.02, 0.0, 0.43), 15.0),
    "parking": ((0.50, 0.0, 0.0, 0.50), 1.5),
    "bike": ((0.0, 0.0, 0.0, 1.0), 12.0),
    "sidewalk": ((0.0, 0.0, 0.85, 0.15), 4.0),
}


@dataclasses.dataclass(frozen=True)
class TrafficMix:
    """Per row kind (index ROW_KINDS): class mix, mean gap (m), occupancy; and the highway share."""

    mix: np.ndarray        # (K, 4)
    gap: np.ndarray        # (K,)
    occupancy: np.ndarray  # (K,)
    highway_prob: float


def _traffic_mix(overrides: dict, highway_prob: float) -> TrafficMix:
    rows = [(*overrides.get(k, _ROW_TABLE[k][:2]), _ROW_TABLE[k][2]) for k in ROW_KINDS]
    return TrafficMix(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                      np.array([r[2] for r in rows]), highway_prob)


TRAFFIC_MIXES = {"nuscenes": _traffic_mix({}, 0.35), "vod": _traffic_mix(_VOD_ROWS, 0.0)}
_TABLE = [_ROW_TABLE[k] for k in ROW_KINDS]
YAW_NOISE = np.deg2rad([t[3] for t in _TABLE])
LATERAL = np.array([t[4] for t in _TABLE])
SIZE_MEAN = np.array([CLASS_PROFILES[c].size_mean for c in CLASSES])
SIZE_STD = np.array([CLASS_PROFILES[c].size_std for c in CLASSES])
# Moving speed (mean, std, low, high) m/s per class; highway traffic runs faster.
SPEED_URBAN = np.array([(10.0, 3.0, 2.0, 16.0), (8.0, 2.5, 2.0, 14.0), (1.3, 0.3, 0.5, 2.2), (4.5, 1.2, 1.5, 8.0)])
SPEED_HIGHWAY = np.array([(27.0, 4.0, 15.0, 38.0), (23.0, 2.5, 15.0, 28.0), (1.3, 0.3, 0.5, 2.2), (4.5, 1.2, 1.5, 8.0)])
LANE, PARKING, SIDEWALK = (ROW_KINDS.index(k) for k in ("lane", "parking", "sidewalk"))


@dataclasses.dataclass(frozen=True)
class Actors:
    center: np.ndarray    # (M, 3)
    size: np.ndarray      # (M, 3) (w, l, h)
    yaw: np.ndarray       # (M,)
    velocity: np.ndarray  # (M, 2)
    cls: np.ndarray       # (M,) int index into CLASSES

    def __len__(self):
        return len(self.cls)

    def center_at(self, t: np.ndarray) -> np.ndarray:
        """(S, M, 2) BEV centres at times t (S,), constant velocity."""
        return self.center[None, :, :2] + self.velocity[None] * np.asarray(t)[:, None, None]


@dataclasses.dataclass(frozen=True)
class EgoMotion:
    speed: float     # m/s along the ego heading
    yaw_rate: float  # rad/s

    def pose(self, t: np.ndarray):
        """Sensor position (S, 2), heading (S,) and velocity (S, 2) at times t (S,), constant turn."""
        t = np.asarray(t, np.float64)
        yaw = self.yaw_rate * t
        if abs(self.yaw_rate) < 1e-6:
            xy = np.stack([self.speed * t, np.zeros_like(t)], -1)
        else:
            r = self.speed / self.yaw_rate
            xy = np.stack([r * np.sin(yaw), r * (1 - np.cos(yaw))], -1)
        vel = self.speed * np.stack([np.cos(yaw), np.sin(yaw)], -1)
        return xy, yaw, vel


@dataclasses.dataclass(frozen=True)
class Scene:
    layout: Layout
    actors: Actors
    ego: EgoMotion


def sample_scene(rng: np.random.Generator, cfg: SyntheticConfig) -> Scene:
    traffic = TRAFFIC_MIXES[cfg.traffic_mix]
    layout = sample_layout(rng, highway_prob=traffic.highway_prob)
    lanes = layout.rows.kind == LANE
    jam = lanes & (rng.random(len(lanes)) < (0.05 if layout.highway else 0.25))  # queued lanes barely move
    actors = _place_actors(rng, layout, jam, cfg.level.traffic, -cfg.sensor_height_m, traffic)
    return Scene(layout, actors, _sample_ego(rng, layout.highway))


def _sample_ego(rng, highway: bool) -> EgoMotion:
    if highway:
        speed = rng.uniform(18.0, 32.0)
    else:
        speed = 0.0 if rng.random() < 0.2 else rng.uniform(3.0, 14.0)
    return EgoMotion(float(speed), float(rng.normal(0.0, 0.02)))


def _place_actors(rng, layout: Layout, jam: np.ndarray, traffic: float, ground_z: float,
                  table: TrafficMix = TRAFFIC_MIXES["nuscenes"]) -> Actors:
    rows = layout.rows
    kind = rows.kind
    mix, gap = table.mix[kind], table.gap[kind].copy()
    lane = kind == LANE
    if layout.highway:
        mix[lane], gap[lane] = _HIGHWAY_LANE
    gap = np.where(jam, 2.5, gap) / traffic
    shape = (len(rows), SLOTS)
    cls = (rng.random(shape)[..., None] > np.cumsum(mix, -1)[:, None, :-1]).sum(-1)
    size = SIZE_MEAN[cls] * np.clip(1 + SIZE_STD[cls] / SIZE_MEAN[cls] * rng.standard_normal(shape + (3,)), 0.6, 1.6)
    step = size[..., 1] + rng.exponential(1.0, shape) * gap[:, None]
    s = rows.s_lo[:, None] - rng.random(len(rows))[:, None] * gap[:, None] + np.cumsum(step, 1) - size[..., 1] / 2
    half = size[..., 1] / 2
    keep = ((s + half <= rows.s_hi[:, None]) & ((s + half < rows.ex_lo[:, None]) | (s - half > rows.ex_hi[:, None]))
            & (rng.random(shape) < table.occupancy[kind][:, None]))
    r, _ = np.nonzero(keep)
    cls, size, s, k = cls[keep], size[keep], s[keep], kind[r]
    lateral = rng.standard_normal(len(r)) * LATERAL[k]
    lateral = np.where(k == SIDEWALK, rng.uniform(-1, 1, len(r)) * LATERAL[k], lateral)
    d = rows.direction()[r]
    xy = rows.origin[r] + s[:, None] * d + lateral[:, None] * np.stack([-d[:, 1], d[:, 0]], -1)
    speed, yaw = _motion(rng, layout, r, k, cls, jam)
    ok = ~((np.abs(xy[:, 0]) < 5.0) & (np.abs(xy[:, 1]) < 2.2))  # not on top of the ego car
    center = np.concatenate([xy, (ground_z + size[:, 2:] / 2)], 1)
    vel = speed[:, None] * np.stack([np.cos(yaw), np.sin(yaw)], -1)
    return Actors(center[ok], size[ok], yaw[ok], vel[ok], cls[ok])


def _motion(rng, layout, r, k, cls, jam):
    """Speed and heading per actor: lane-aligned with noise; parked and standing actors are still."""
    n = len(r)
    table = SPEED_HIGHWAY if layout.highway else SPEED_URBAN
    mean, std, lo, hi = table[cls].T
    speed = np.clip(mean + std * rng.standard_normal(n), lo, hi)
    speed = np.where(jam[r], rng.uniform(0.0, 2.0, n), speed)
    still = (k == PARKING) | ((k == SIDEWALK) & (rng.random(n) < np.where(cls == 2, 0.35, 0.5)))
    speed = np.where(still, 0.0, speed)
    travel = layout.rows.travel[r]
    travel = np.where(travel == 0, rng.choice([-1, 1], n), travel)
    yaw = layout.rows.theta[r] + (travel < 0) * np.pi + rng.standard_normal(n) * YAW_NOISE[k]
    standing = still & (k == SIDEWALK)  # people standing about face anywhere
    yaw = np.where(standing, rng.uniform(-np.pi, np.pi, n), yaw)
    return speed, np.arctan2(np.sin(yaw), np.cos(yaw))

"""Point scatterers: what the radar actually sees of objects, clutter and multipath.

- Extended bodies: `body_scatterers` points, a share `body_interior_share` (default 1/2) anywhere
  on the object's footprint (wheels, wheel arches, underbody, cabin: the radar sees more than the
  silhouette) and the rest on the faces of its rectangle that face the radar, with exponential
  (Swerling-like) power weights. So a car spans up to its length in range (4.6 m = 24 bins of
  0.195 m) from every aspect, seen end-on as well. Every
  point of a rigid body moves with the body, and its radial velocity is that velocity projected
  on its own line of sight, so wide objects close by also spread a little in Doppler.
- Micro-Doppler: persons carry 'gait' scatterers (two legs and two arms, a mid and an end point
  each) whose speed along the heading is v (1 + a sin(phase + offset)), a = 0.5 / 1.0 for knee /
  foot and 0.3 / 0.6 for elbow / hand, legs in antiphase and arms opposite their leg (feet swing
  between 0 and 2 v); bicycles and motorcycles carry 'wheels' scatterers, rim points at random
  angles alpha from the ground contact moving at v (1 - cos alpha) along the heading (0 at the
  contact, 2 v on top). Within one frame (a few ms) these speeds are constant, so limbs and
  wheels spread over Doppler bins, not over time.
- Static clutter (velocity exactly 0: a static sensor): ground patches, building facades (lines
  of scatterers) and parked vehicles (car layouts); never labelled. Benchmark v2 adds area
  clutter at every range and strong point reflectors (`static_scene_scatterers`): the area
  clutter of a range bin is sigma0 times the patch the field of view cuts from it, R fov dR, so
  its power falls as R^-3 where a point target's falls as R^-4 (beam-limited clutter), split over
  `area_cells_per_bin` scatterers with a log-normal texture (their random phases give the
  speckle) and a per-frame sigma0 (an open road against a street lined with walls and kerbs);
  poles, signs and posts are single strong scatterers at random ranges.
- Multipath ghosts: a copy of a moving object's scatterers at a longer path (range + 1..6 m), the
  same Doppler, another azimuth, 8..15 dB weaker; never labelled.
RCS is split over an object's scatterers (weights sum to 1), so the object's total follows the
class's log-normal law.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .config import ClassProfile, RDSyntheticConfig
from .scene import Actor, sample_rcs_dbsm

# (amplitude a, phase offset) of the gait points: knee, foot (per leg), elbow, hand (per arm)
GAIT_POINTS = ((0.5, 0.0), (1.0, 0.0), (0.5, math.pi), (1.0, math.pi),     # left leg, right leg
               (0.3, math.pi), (0.6, math.pi), (0.3, 0.0), (0.6, 0.0))     # left arm, right arm
RIM_POINTS_PER_WHEEL = 4


@dataclasses.dataclass(frozen=True)
class Scatterers:
    """Point scatterers as parallel arrays (all float64, shape (K,))."""
    range_m: np.ndarray
    velocity_mps: np.ndarray   # radial, positive = receding
    azimuth_rad: np.ndarray
    rcs_m2: np.ndarray         # linear
    phase_rad: np.ndarray      # carrier phase at the first sample (random: sub-wavelength position)

    def __len__(self) -> int:
        return len(self.range_m)

    @classmethod
    def empty(cls) -> "Scatterers":
        z = np.zeros(0)
        return cls(z, z, z, z, z)

    def select(self, keep) -> "Scatterers":
        return Scatterers(*(getattr(self, f.name)[keep] for f in dataclasses.fields(self)))

    @classmethod
    def concat(cls, parts: list["Scatterers"]) -> "Scatterers":
        if not parts:
            return cls.empty()
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(cls)))

    @classmethod
    def from_points(cls, rng: np.random.Generator, xy: np.ndarray, vel_xy: np.ndarray, rcs_m2: np.ndarray):
        """Scatterers at points xy (K, 2) moving with vel_xy (K, 2)."""
        r = np.hypot(xy[:, 0], xy[:, 1])
        radial = np.einsum("kd,kd->k", vel_xy, xy) / np.maximum(r, 1e-9)
        return cls(r, radial, np.arctan2(xy[:, 1], xy[:, 0]), np.asarray(rcs_m2, np.float64),
                   rng.uniform(0, 2 * math.pi, len(r)))


def _rotation(heading: float) -> np.ndarray:
    c, s = math.cos(heading), math.sin(heading)
    return np.array([[c, -s], [s, c]])


def body_points(rng: np.random.Generator, n: int, center, heading: float, size, interior_share: float) -> np.ndarray:
    """n points of a (width, length) rectangle: a share `interior_share` anywhere on its footprint
    (wheels, wheel arches, underbody, cabin: the radar sees more than the silhouette), the rest
    uniformly on the faces that face the radar."""
    w, l = size
    inside = rng.binomial(n, interior_share)
    local = np.stack([rng.uniform(-l / 2, l / 2, inside), rng.uniform(-w / 2, w / 2, inside)], 1)
    rot, c = _rotation(heading), np.asarray(center, np.float64)
    return np.concatenate([local @ rot.T + c, outline_points(rng, n - inside, center, heading, size)])


def outline_points(rng: np.random.Generator, n: int, center, heading: float, size) -> np.ndarray:
    """n points uniformly on the faces of the (width, length) rectangle that face the radar."""
    w, l = size
    # faces in the local frame (x along the heading): (midpoint, outward normal, half-extent vector)
    faces = [((l / 2, 0.0), (1.0, 0.0), (0.0, w / 2)), ((-l / 2, 0.0), (-1.0, 0.0), (0.0, w / 2)),
             ((0.0, w / 2), (0.0, 1.0), (l / 2, 0.0)), ((0.0, -w / 2), (0.0, -1.0), (l / 2, 0.0))]
    rot, c = _rotation(heading), np.asarray(center, np.float64)
    mids = np.array([f[0] for f in faces]) @ rot.T + c
    normals = np.array([f[1] for f in faces]) @ rot.T
    visible = np.einsum("fd,fd->f", normals, -mids) > 0
    if not visible.any():  # the radar inside the rectangle: use all faces
        visible[:] = True
    half = np.array([f[2] for f in faces]) @ rot.T
    lengths = 2 * np.linalg.norm(half, axis=1) * visible
    face = rng.choice(4, size=n, p=lengths / lengths.sum())
    t = rng.uniform(-1, 1, n)
    return mids[face] + t[:, None] * half[face]


def object_scatterers(rng: np.random.Generator, actor: Actor, profile: ClassProfile,
                      interior_share: float = 0.5) -> Scatterers:
    heading = np.array([math.cos(actor.heading), math.sin(actor.heading)])
    total = 10 ** (actor.rcs_dbsm / 10)
    n = profile.body_scatterers
    xy = body_points(rng, n, actor.center, actor.heading, actor.size, interior_share)
    weights = rng.exponential(1.0, n)
    body = Scatterers.from_points(rng, xy, np.tile(actor.speed * heading, (n, 1)),
                                  total * (1 - profile.micro_share) * weights / weights.sum())
    if profile.micro == "none" or profile.micro_share == 0:
        return body
    speeds, offsets = micro_speeds(rng, profile.micro, actor.speed, actor.size[1])
    xy = np.asarray(actor.center) + offsets @ _rotation(actor.heading).T
    micro = Scatterers.from_points(rng, xy, speeds[:, None] * heading[None, :],
                                   np.full(len(speeds), total * profile.micro_share / len(speeds)))
    return Scatterers.concat([body, micro])


def micro_speeds(rng: np.random.Generator, kind: str, speed: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Speeds along the heading (K,) and local offsets (K, 2) of the limb or wheel points."""
    if kind == "gait":
        phase = rng.uniform(0, 2 * math.pi)
        amp = np.array([a for a, _ in GAIT_POINTS])
        off = np.array([o for _, o in GAIT_POINTS])
        speeds = speed * (1 + amp * np.sin(phase + off))
        offsets = rng.uniform(-0.25, 0.25, (len(amp), 2))
        return speeds, offsets
    alpha = rng.uniform(0, 2 * math.pi, 2 * RIM_POINTS_PER_WHEEL)  # rim angle from the ground contact
    speeds = speed * (1 - np.cos(alpha))
    axle = max(length / 2 - 0.35, 0.1)
    along = np.repeat([axle, -axle], RIM_POINTS_PER_WHEEL) + 0.3 * np.sin(alpha)
    return speeds, np.stack([along, np.zeros_like(along)], 1)


def _uniform_points(rng, n: int, r_lo: float, r_hi: float, half_fov: float) -> np.ndarray:
    """n points uniform in range [r_lo, r_hi] (an empty interval: r_lo) and in azimuth."""
    r = rng.uniform(r_lo, max(r_lo, r_hi), n)
    az = rng.uniform(-half_fov, half_fov, n)
    return np.stack([r * np.cos(az), r * np.sin(az)], 1)


def clutter_scatterers(rng: np.random.Generator, cfg: RDSyntheticConfig) -> Scatterers:
    """Static returns: ground, building facades, parked vehicles (radial velocity 0)."""
    c, half_fov = cfg.clutter, math.radians(cfg.fov_deg / 2)
    near, far = cfg.min_range_m, cfg.max_range_m  # small sensors: every interval clipped to these
    parts = []
    n = rng.poisson(c.ground_scatterers)
    xy = _uniform_points(rng, n, cfg.min_range_m, cfg.max_range_m, half_fov)
    rcs = 10 ** ((c.ground_rcs_dbsm + c.ground_rcs_sd_db * rng.standard_normal(n)) / 10)
    parts.append(Scatterers.from_points(rng, xy, np.zeros_like(xy), rcs))
    for _ in range(rng.integers(0, c.max_buildings + 1)):
        length = rng.uniform(*c.building_length_m)
        lo, hi = np.clip(c.building_range_m, near, far)
        start = _uniform_points(rng, 1, lo, hi, half_fov)[0]
        direction = rng.uniform(-math.pi, math.pi)
        k = max(1, int(length / c.building_spacing_m))
        xy = start + np.outer(np.linspace(0, length, k), [math.cos(direction), math.sin(direction)])
        r = np.hypot(xy[:, 0], xy[:, 1])
        xy = xy[(r < far) & (r >= near)]
        rcs = 10 ** ((c.building_rcs_dbsm + c.building_rcs_sd_db * rng.standard_normal(len(xy))) / 10)
        parts.append(Scatterers.from_points(rng, xy, np.zeros_like(xy), rcs))
    car = cfg.profile("car") if "car" in cfg.classes else None
    for _ in range(rng.poisson(c.parked_vehicles) if car else 0):
        center = _uniform_points(rng, 1, min(near + 2, far), far - 3, half_fov)[0]
        xy = body_points(rng, car.body_scatterers, center, rng.uniform(-math.pi, math.pi), car.size_m,
                         cfg.body_interior_share)
        weights = rng.exponential(1.0, len(xy))
        total = 10 ** (sample_rcs_dbsm(rng, car) / 10)
        parts.append(Scatterers.from_points(rng, xy, np.zeros_like(xy), total * weights / weights.sum()))
    return Scatterers.concat(parts)


def area_clutter(rng: np.random.Generator, cfg: RDSyntheticConfig) -> Scatterers:
    """Beam-limited area clutter from area_min_range_m to the sensor's last range bin (the scene goes
    on past the labelled range; the IF low-pass rolls it off): RCS sigma0 R fov dR per range bin,
    area_cells_per_bin scatterers per bin (module docstring)."""
    c, sensor = cfg.clutter, cfg.sensor
    near, far = min(c.area_min_range_m, sensor.max_range_m), sensor.max_range_m
    n = int(round(c.area_cells_per_bin * (far - near) / sensor.range_resolution_m))
    if n < 1:
        return Scatterers.empty()
    fov = math.radians(cfg.fov_deg)
    xy = _uniform_points(rng, n, near, far, fov / 2)
    r = np.hypot(xy[:, 0], xy[:, 1])
    sigma0_db = c.area_sigma0_db + c.area_sigma0_sd_db * rng.standard_normal()
    texture_db = c.area_texture_sd_db * rng.standard_normal(n)
    patch_m2 = r * fov * sensor.range_resolution_m / c.area_cells_per_bin
    return Scatterers.from_points(rng, xy, np.zeros_like(xy), patch_m2 * 10 ** ((sigma0_db + texture_db) / 10))


def point_reflectors(rng: np.random.Generator, cfg: RDSyntheticConfig) -> Scatterers:
    """Poles, signs and posts: Poisson(poles) single scatterers, uniform over the scene."""
    c = cfg.clutter
    n = rng.poisson(c.poles)
    xy = _uniform_points(rng, n, cfg.min_range_m, cfg.max_range_m, math.radians(cfg.fov_deg / 2))
    rcs = 10 ** ((c.pole_rcs_dbsm + c.pole_rcs_sd_db * rng.standard_normal(n)) / 10)
    return Scatterers.from_points(rng, xy, np.zeros_like(xy), rcs)


def static_scene_scatterers(rng: np.random.Generator, cfg: RDSyntheticConfig) -> Scatterers:
    """Benchmark v2's static scene on top of `clutter_scatterers`: area clutter and point reflectors.
    Nothing is drawn for a mechanism that is off, so benchmark v1's samples stay as they were."""
    return Scatterers.concat([area_clutter(rng, cfg), point_reflectors(rng, cfg)])


def ghost_of(rng: np.random.Generator, s: Scatterers, cfg: RDSyntheticConfig) -> Scatterers:
    """A multipath copy: longer path, same Doppler, another azimuth, weaker."""
    c = cfg.clutter
    extra = rng.uniform(*c.ghost_extra_range_m)
    loss = 10 ** (-rng.uniform(*c.ghost_loss_db) / 10)
    az = rng.uniform(-1, 1) * math.radians(cfg.fov_deg / 2)
    ghost = Scatterers(s.range_m + extra, s.velocity_mps.copy(), np.full(len(s), az), s.rcs_m2 * loss,
                       rng.uniform(0, 2 * math.pi, len(s)))
    return ghost.select(ghost.range_m < cfg.max_range_m)  # beyond it the IF filter takes it out

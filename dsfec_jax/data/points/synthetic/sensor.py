"""The radar itself: when and where each sweep happened, what it can see, and how it measures.

Every source (objects, structures, false alarms, ghosts) hands over `Echoes`: true scatterer
positions in the current ego frame with the sweep they belong to. `measure` turns them into
nuScenes-style points: polar noise around the sensor position of that sweep (so lateral error
grows with range), RCS in rcs_quantum_db steps, and the ego-motion-compensated radial velocity
projected on the line of sight (vx_comp, vy_comp), which is all nuScenes gives.

With point_format="vod" the same measurement is written as View-of-Delft columns: the Doppler
v_r relative to the moving sensor and v_r_comp = v_r + (estimated ego velocity) . u, both
along the 3D line of sight u (VoD's own v_r - v_r_comp fits -v_ego . u with the 3D unit
vector to 0.005 m/s rms in example frame 01047, the 2D one only to 0.02), and time = -k.
Sign: positive = receding, so a static point ahead of a forward-driving ego has v_r < 0,
v_r_comp ~ 0, and v_r - v_r_comp = -v_ego_est . u (as in VoD's data).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .config import SyntheticConfig
from .scene import EgoMotion

R_REF = 10.0  # m, reference range of snr_ref_db and of the point-count law


@dataclasses.dataclass(frozen=True)
class Sweeps:
    t: np.ndarray        # (S,) sweep times, <= 0 (sweep 0 is the current one)
    dt: np.ndarray       # (S,) -t, the nuScenes time lag feature
    pos: np.ndarray      # (S, 2) sensor position in the current frame
    yaw: np.ndarray      # (S,) sensor heading
    vel: np.ndarray      # (S, 2) true sensor velocity
    vel_est: np.ndarray  # (S, 2) odometry estimate used for the compensation


def make_sweeps(rng: np.random.Generator, cfg: SyntheticConfig, ego: EgoMotion) -> Sweeps:
    dt = cfg.sweep_offsets
    pos, yaw, vel = ego.pose(-dt)
    err = rng.standard_normal(vel.shape) * cfg.ego_velocity_noise_mps * cfg.level.noise
    return Sweeps(-dt, dt, pos, yaw, vel, vel + err)


@dataclasses.dataclass(frozen=True)
class Echoes:
    xy: np.ndarray          # (P, 2) true scatterer position at its sweep time
    z: np.ndarray           # (P,) true height
    sweep: np.ndarray       # (P,) int
    vel: np.ndarray         # (P, 2) scatterer velocity over ground
    rcs_db: np.ndarray      # (P,) dBsm
    owner: np.ndarray       # (P,) actor index, -1 for clutter
    source: np.ndarray      # (P,) int index into config.SOURCES
    doppler_std: np.ndarray  # (P,) extra radial-velocity spread (micro-Doppler of limbs, wheels)

    def __len__(self):
        return len(self.sweep)

    def select(self, keep) -> "Echoes":
        return Echoes(*(getattr(self, f.name)[keep] for f in dataclasses.fields(self)))

    @staticmethod
    def concat(parts) -> "Echoes":
        return Echoes(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(Echoes)))


def wrap(a):
    """Angle to [-pi, pi] (rint is several times faster than a float modulo)."""
    return a - 2 * np.pi * np.rint(a * (0.5 / np.pi))


def polar(xy: np.ndarray, sensor_xy: np.ndarray):
    """Range and world azimuth of xy as seen from sensor_xy (broadcasting)."""
    d = xy - sensor_xy
    return np.hypot(d[..., 0], d[..., 1]), np.arctan2(d[..., 1], d[..., 0])


def in_view(cfg: SyntheticConfig, rng_m, az_world, sensor_yaw):
    return ((np.abs(wrap(az_world - sensor_yaw)) <= np.deg2rad(cfg.fov_deg) / 2)
            & (rng_m <= cfg.max_range_m) & (rng_m >= 0.5))


def snr_db(cfg: SyntheticConfig, rcs_db, rng_m):
    """Radar equation: SNR falls with R^4; referenced to a 0 dBsm target at R_REF."""
    return rcs_db - 40.0 * np.log10(np.maximum(rng_m, 0.5) / R_REF) + cfg.snr_ref_db + cfg.level.snr_offset_db


def detectable(cfg: SyntheticConfig, rcs_db, rng_m):
    return snr_db(cfg, rcs_db, rng_m) >= cfg.snr_threshold_db


def measure(rng: np.random.Generator, cfg: SyntheticConfig, sweeps: Sweeps, e: Echoes) -> np.ndarray:
    """(P, 7) points with cfg.point_features columns, in the current ego frame."""
    noise = cfg.level.noise
    s = sweeps.pos[e.sweep]
    r, az = polar(e.xy, s)
    n = len(e)
    r_m = r + rng.standard_normal(n) * cfg.range_noise_m * noise
    az_m = az + rng.standard_normal(n) * np.deg2rad(cfg.azimuth_noise_deg) * noise
    u_true = np.stack([np.cos(az), np.sin(az)], -1)
    u_m = np.stack([np.cos(az_m), np.sin(az_m)], -1)
    xy = s + r_m[:, None] * u_m
    if cfg.elevation:
        z = e.z + r * rng.standard_normal(n) * np.deg2rad(cfg.elevation_noise_deg) * noise
    else:
        z = np.zeros(n)  # no elevation: every point lies in the sensor plane, as nuScenes radar
    vod = cfg.point_format == "vod"
    # Velocities are horizontal, so along a 3D line of sight they shrink by cos(elevation).
    # The nuScenes columns stay 2D projections (frames of existing configs must not change).
    cos_true = _cos_elevation(e.z, r) if vod else 1.0
    cos_m = _cos_elevation(z, r_m) if vod else 1.0
    v_r = (cos_true * np.sum((e.vel - sweeps.vel[e.sweep]) * u_true, -1)
           + rng.standard_normal(n) * np.hypot(cfg.velocity_noise_mps * noise, e.doppler_std))
    # The compensation adds back the (estimated) ego velocity along the *measured* direction.
    v_comp = v_r + cos_m * np.sum(sweeps.vel_est[e.sweep] * u_m, -1)
    rcs = _quantise(e.rcs_db, cfg.rcs_quantum_db)
    if vod:
        cols = (xy[:, 0], xy[:, 1], z, rcs, v_r, v_comp, (-e.sweep).astype(np.float64))  # int: no -0.0
    else:
        cols = (xy[:, 0], xy[:, 1], z, rcs, v_comp * u_m[:, 0], v_comp * u_m[:, 1], sweeps.dt[e.sweep])
    return np.stack(cols, -1).astype(np.float32)


def _cos_elevation(z, r_bev):
    """cos of the elevation angle of a point at height z (sensor at z = 0) and BEV range r_bev."""
    r_bev = np.maximum(r_bev, 1e-3)
    return r_bev / np.hypot(r_bev, z)


def _quantise(rcs_db, quantum_db: float):
    return rcs_db if quantum_db == 0 else np.round(rcs_db / quantum_db) * quantum_db

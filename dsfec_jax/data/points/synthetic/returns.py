"""Radar returns from actors: how many detections each object gives per sweep, and where.

Per sweep and object: a log-normal RCS (class mean, 3GPP sigma split into a persistent part and
per-sweep scintillation, vehicle aspect pattern); the object is detected when its SNR clears the
threshold (R^4 law), and then gives 1 + Poisson(lambda) detections, lambda = c_cls * sigma_lin *
(R_REF / R)^2 saturating at the number of resolution cells its silhouette spans. Detections lie
on the faces the sensor can see, chosen in proportion to their projected width.
"""

from __future__ import annotations

import numpy as np

from .config import ASPECT_COS1_DB, ASPECT_COS2_DB, CLASS_PROFILES, CLASSES, SyntheticConfig
from .scene import Actors
from .sensor import R_REF, Echoes, Sweeps, detectable, in_view, polar, wrap

_P = [CLASS_PROFILES[c] for c in CLASSES]
RCS_SIGMA = np.array([p.rcs_sigma_db for p in _P])
RCS_MEDIAN = np.array([p.rcs_dbsm for p in _P]) - np.log(10) / 20 * RCS_SIGMA ** 2  # log-normal mean fix
ASPECT = np.array([p.aspect_depth for p in _P])
PER_M2 = np.array([p.points_per_m2 for p in _P])
PER_M = np.array([p.points_per_m for p in _P])
MICRO_DOPPLER = np.array([0.05, 0.05, 0.4, 0.3])  # m/s spread of limbs and wheels when moving


def object_echoes(rng: np.random.Generator, cfg: SyntheticConfig, actors: Actors, sweeps: Sweeps) -> Echoes:
    c = actors.center_at(sweeps.t)                       # (S, M, 2)
    r, az = polar(c, sweeps.pos[:, None, :])
    beta = wrap(az + np.pi - actors.yaw[None])          # direction to the sensor, object frame
    rcs_db = _rcs_db(rng, actors.cls, beta)
    seen = in_view(cfg, r, az, sweeps.yaw[:, None]) & detectable(cfg, rcs_db, r)
    w, l = actors.size[:, 0], actors.size[:, 1]
    sb, cb = np.sin(beta), np.cos(beta)
    silhouette = l * np.abs(sb) + w * np.abs(cb)         # width seen from the sensor
    # An imaging radar detects more weak scatterers (more channels, more integration gain:
    # density_scale) and separates more of them along an outline (finer bins: resolution_scale).
    cap = 1.0 + cfg.resolution_scale * PER_M[actors.cls] * silhouette
    raw = cfg.density_scale * PER_M2[actors.cls] * 10 ** (rcs_db / 10) * (R_REF / r) ** 2
    lam = cap * -np.expm1(-raw / cap)                    # saturates at the resolution limit
    count = np.where(seen, 1 + rng.poisson(lam), 0)
    flat = np.repeat(np.arange(count.size), count.ravel())
    k, m = np.divmod(flat, len(actors))
    return _on_faces(rng, actors, c, k, m, sb, cb, rcs_db, count)


def _rcs_db(rng, cls, beta):
    """(S, M) RCS: class median + aspect pattern + persistent and per-sweep log-normal parts."""
    sigma = RCS_SIGMA[cls] / np.sqrt(2)
    aspect = ASPECT[cls] * (ASPECT_COS1_DB * np.cos(beta) + ASPECT_COS2_DB * np.cos(2 * beta))
    persistent = rng.standard_normal(len(cls)) * sigma
    return RCS_MEDIAN[cls] + aspect + persistent + rng.standard_normal(beta.shape) * sigma


def _on_faces(rng, actors, c, k, m, sb, cb, rcs_db, count) -> Echoes:
    """Detections on the visible long side or the visible front/rear, uniform along the face."""
    n = len(k)
    w, l, h = actors.size[m].T
    sb, cb = sb[k, m], cb[k, m]
    side = rng.random(n) * (l * np.abs(sb) + w * np.abs(cb)) < l * np.abs(sb)
    along = rng.random(n) - 0.5
    lx = np.where(side, along * l, np.sign(cb) * l / 2)
    ly = np.where(side, np.sign(sb) * w / 2, along * w)
    cy, sy = np.cos(actors.yaw[m]), np.sin(actors.yaw[m])
    xy = c[k, m] + np.stack([lx * cy - ly * sy, lx * sy + ly * cy], -1)
    z = actors.center[m, 2] - h / 2 + rng.uniform(0.1, 1.0, n) * np.minimum(h, 1.5)
    # The object's energy spreads over its detections; each keeps some of it plus glints.
    rcs = rcs_db[k, m] - 5 * np.log10(count[k, m]) + rng.standard_normal(n) * 2.0
    vel = actors.velocity[m]
    moving = np.hypot(vel[:, 0], vel[:, 1]) > 0.2
    return Echoes(xy, z, k, vel, rcs, m, np.zeros(n, np.int8), MICRO_DOPPLER[actors.cls[m]] * moving)

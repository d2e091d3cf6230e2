"""Everything that is not an annotated object: static structures, false alarms, multipath ghosts.

- Structures (guard-rail posts, building fronts, poles) are fixed scatterers along the layout's
  walls; flat ones reflect best at normal incidence. They stand still, so their compensated
  velocity is only noise.
- False alarms are CFAR noise hits, uniform in range and azimuth, RCS ~ N(-13, 9^2) dB (assumed;
  see config.py);
  most sit at a static Doppler (ground, vegetation), some at a random one.
- Ghosts are object detections mirrored in a rail or wall between which and the sensor the
  object stands: the image appears beyond the wall, with the mirrored velocity, weaker.
"""

from __future__ import annotations

import numpy as np

from .config import SyntheticConfig
from .layout import WALL_KINDS, Layout, Lines
from .sensor import Echoes, Sweeps, detectable, in_view, polar

# Per wall kind: scatterer spacing (m), RCS mean and sigma (dBsm), facade-like incidence loss.
SPACING = np.array([1.5, 1.2, 25.0])
RCS_MEAN = np.array([2.0, 4.0, 8.0])
RCS_SIGMA = np.array([4.0, 5.0, 3.0])
FLAT = np.array([True, True, False])
MAX_SLOTS = 96
REFLECTORS = (WALL_KINDS.index("rail"), WALL_KINDS.index("building"))
RAIL = WALL_KINDS.index("rail")
RAIL_TOP = 1.5  # m above the ground: the highest a rail scatterer sits, whatever structure_top_m
FA_RCS = (-13.0, 9.0)
FA_RANDOM_DOPPLER = 0.25  # share of false alarms at a random Doppler bin
FA_DOPPLER_SPAN = 15.0    # m/s, half-width of that random Doppler


def structure_echoes(rng: np.random.Generator, cfg: SyntheticConfig, layout: Layout, sweeps: Sweeps,
                     ground_z: float) -> Echoes:
    q, kind, normal = _scatterers(rng, layout.walls, cfg.level.clutter * cfg.clutter_scale,
                                  round(MAX_SLOTS * cfg.clutter_scale))
    r, az = polar(q[None], sweeps.pos[:, None, :])                                   # (S, Q)
    rcs = RCS_MEAN[kind] + rng.standard_normal(r.shape) * RCS_SIGMA[kind]
    cos_inc = np.abs(np.cos(az) * normal[:, 0] + np.sin(az) * normal[:, 1])
    rcs = rcs + np.where(FLAT[kind], 10 * np.log10(0.1 + 0.9 * cos_inc ** 2), 0.0)  # grazing walls are dim
    hit = in_view(cfg, r, az, sweeps.yaw[:, None]) & detectable(cfg, rcs, r)
    k, i = np.nonzero(hit)
    n = len(k)
    xy = q[i] + rng.standard_normal((n, 2)) * 0.15  # the scattering centre wanders over a post or facade
    # Rails are low; facades and poles show scatterers as high as the sensor resolves them.
    top = np.where(kind[i] == RAIL, min(RAIL_TOP, cfg.structure_top_m), cfg.structure_top_m)
    return Echoes(xy, ground_z + rng.uniform(0.3, top, n), k, np.zeros((n, 2)), rcs[k, i],
                  np.full(n, -1), np.full(n, 1, np.int8), np.zeros(n))


def _scatterers(rng, walls: Lines, density: float, max_slots: int = MAX_SLOTS):
    """Fixed scatterer positions along the walls, stratified with jitter: (Q, 2), kind, normal.

    At most max_slots per wall: a denser clutter_scale brings proportionally more slots, so the
    stretch of wall they cover stays what it is without it."""
    if len(walls) == 0:
        return np.zeros((0, 2)), np.zeros(0, int), np.zeros((0, 2))
    spacing = (SPACING / np.where(FLAT, density, 1.0))[walls.kind]
    slots = walls.s_lo[:, None] + (np.arange(max_slots) + rng.random((len(walls), max_slots))) * spacing[:, None]
    keep = (slots <= walls.s_hi[:, None]) & ((slots < walls.ex_lo[:, None]) | (slots > walls.ex_hi[:, None]))
    w, _ = np.nonzero(keep)
    d = walls.direction()[w]
    q = walls.origin[w] + slots[keep][:, None] * d
    return q, walls.kind[w], np.stack([-d[:, 1], d[:, 0]], -1)


def false_alarm_echoes(rng: np.random.Generator, cfg: SyntheticConfig, sweeps: Sweeps, ground_z: float) -> Echoes:
    counts = rng.poisson(cfg.false_alarms_per_sweep * cfg.level.false_alarms, cfg.num_sweeps)
    k = np.repeat(np.arange(cfg.num_sweeps), counts)
    n = len(k)
    r = rng.uniform(1.0, cfg.max_range_m, n)
    az = sweeps.yaw[k] + (rng.random(n) - 0.5) * np.deg2rad(cfg.fov_deg)
    u = np.stack([np.cos(az), np.sin(az)], -1)
    v_radial = np.where(rng.random(n) < FA_RANDOM_DOPPLER, rng.uniform(-1, 1, n) * FA_DOPPLER_SPAN,
                        rng.standard_normal(n) * 0.3)
    rcs = FA_RCS[0] + rng.standard_normal(n) * FA_RCS[1]
    return Echoes(sweeps.pos[k] + r[:, None] * u, ground_z + rng.uniform(0.0, 2.0, n), k, v_radial[:, None] * u,
                  rcs, np.full(n, -1), np.full(n, 2, np.int8), np.zeros(n))


def ghost_echoes(rng: np.random.Generator, cfg: SyntheticConfig, layout: Layout, sweeps: Sweeps,
                 obj: Echoes) -> Echoes:
    """Mirror a few object echoes in the nearest wall that stands beyond them (seen from the sensor)."""
    walls = layout.walls
    refl = np.isin(walls.kind, REFLECTORS)
    pick = rng.random(len(obj)) < cfg.ghost_prob * cfg.level.ghosts
    if not refl.any() or not pick.any():
        return obj.select(np.zeros(len(obj), bool))
    e = obj.select(pick)
    d = walls.direction()[refl]
    n = np.stack([-d[:, 1], d[:, 0]], -1)                                             # (L, 2)
    o = walls.origin[refl]
    dist_p = np.einsum("pld,ld->pl", e.xy[:, None] - o[None], n)                      # (G, L)
    dist_s = np.einsum("pld,ld->pl", sweeps.pos[e.sweep][:, None] - o[None], n)
    usable = np.sign(dist_p) == np.sign(dist_s)                                       # same side as the sensor
    j = np.argmin(np.where(usable, np.abs(dist_p), np.inf), axis=1)
    g = np.arange(len(e))
    nj = n[j]
    xy = e.xy - 2 * dist_p[g, j][:, None] * nj
    vel = e.vel - 2 * np.sum(e.vel * nj, -1)[:, None] * nj
    s_along = np.sum((xy - o[j]) * d[j], -1)
    lines = np.flatnonzero(refl)[j]
    on_wall = ((s_along >= walls.s_lo[lines]) & (s_along <= walls.s_hi[lines])
               & ((s_along < walls.ex_lo[lines]) | (s_along > walls.ex_hi[lines])))
    rcs = e.rcs_db - cfg.ghost_loss_db + rng.standard_normal(len(e)) * 2.0
    r, az = polar(xy, sweeps.pos[e.sweep])
    ok = usable[g, j] & on_wall & in_view(cfg, r, az, sweeps.yaw[e.sweep]) & detectable(cfg, rcs, r)
    ghosts = Echoes(xy, e.z, e.sweep, vel, rcs, np.full(len(e), -1), np.full(len(e), 3, np.int8), e.doppler_std)
    return ghosts.select(ok)

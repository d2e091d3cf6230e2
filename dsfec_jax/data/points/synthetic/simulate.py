"""One frame from one random stream: scene -> sweeps -> echoes -> occlusion -> measurement.

Points of all sweeps are already in the current ego frame (scene coordinates are), so the
multi-sweep accumulation needs no extra transform: static scatterers line up across sweeps,
moving objects leave a trail of their past positions, told apart by the dt column.

A config with a camera view (camera_fov_deg < 360, the 4D/VoD profile) annotates only boxes
partly inside it and keeps only the points inside it, as VoD annotates and its baseline crops.
"""

from __future__ import annotations

import numpy as np

from ....boxes.geometry import bev_corners
from ..frame import Boxes, Frame
from .clutter import false_alarm_echoes, ghost_echoes, structure_echoes
from .config import CLASSES, SOURCES, SyntheticConfig
from .occlusion import shadowed
from .returns import object_echoes
from .scene import Actors, sample_scene
from .sensor import Echoes, make_sweeps, measure


def simulate(rng: np.random.Generator, cfg: SyntheticConfig, frame_id: str = "", meta: dict | None = None) -> Frame:
    scene = sample_scene(rng, cfg)
    sweeps = make_sweeps(rng, cfg, scene.ego)
    ground = -cfg.sensor_height_m
    solid = Echoes.concat([object_echoes(rng, cfg, scene.actors, sweeps),
                           structure_echoes(rng, cfg, scene.layout, sweeps, ground)])
    lost = shadowed(scene.actors, sweeps, solid, cfg.max_range_m) & (rng.random(len(solid)) < cfg.occlusion_prob)
    solid = solid.select(~lost)
    ghosts = ghost_echoes(rng, cfg, scene.layout, sweeps, solid.select(solid.source == 0))
    echoes = Echoes.concat([solid, ghosts, false_alarm_echoes(rng, cfg, sweeps, ground)])
    points = measure(rng, cfg, sweeps, echoes)
    keep = _near_grid(cfg, points) & _in_camera_view(cfg, points[:, :2])
    # Shuffle: a fixed source order would let point-order truncation in pillars leak labels.
    order = rng.permutation(np.flatnonzero(keep))
    boxes, box_of_actor = _boxes(cfg, scene.actors)
    point_box = np.append(box_of_actor, -1)[echoes.owner[order]].astype(np.int32)  # owner -1 -> -1
    meta = dict(meta or {})
    meta.update(
        point_source=echoes.source[order], point_box=point_box,
        num_points=np.bincount(point_box[point_box >= 0], minlength=len(boxes)).astype(np.int32),
        source_names=SOURCES, scene="highway" if scene.layout.highway else "urban",
        ego_velocity=sweeps.vel[0].astype(np.float32), ego_yaw_rate=float(scene.ego.yaw_rate),
        num_sweeps=cfg.num_sweeps, difficulty=cfg.difficulty)
    return Frame(points[order], cfg.point_features, boxes, frame_id, "synthetic", meta)


def _near_grid(cfg: SyntheticConfig, points: np.ndarray) -> np.ndarray:
    g, m = cfg.grid, cfg.keep_margin_m
    return ((points[:, 0] >= g.x_range[0] - m) & (points[:, 0] <= g.x_range[1] + m)
            & (points[:, 1] >= g.y_range[0] - m) & (points[:, 1] <= g.y_range[1] + m))


def _in_camera_view(cfg: SyntheticConfig, xy: np.ndarray) -> np.ndarray:
    """(N,) bool: inside the camera's horizontal field of view (all True without a camera view)."""
    if cfg.camera_fov_deg >= 360:
        return np.ones(len(xy), bool)
    return np.abs(np.arctan2(xy[..., 1], xy[..., 0])) <= np.deg2rad(cfg.camera_fov_deg) / 2


def _annotated(cfg: SyntheticConfig, actors: Actors) -> np.ndarray:
    """(M,) bool: centre inside the grid now, and (VoD's rule) partly inside the camera view and
    within annotate_range_m."""
    x, y = actors.center[:, 0], actors.center[:, 1]
    inside = cfg.grid.contains(x, y)
    if cfg.camera_fov_deg < 360:
        corners = bev_corners(actors.center[:, :2], actors.size[:, :2], actors.yaw)   # (M, 4, 2)
        inside &= _in_camera_view(cfg, np.concatenate([corners, actors.center[:, None, :2]], 1)).any(1)
    if cfg.annotate_range_m is not None:
        inside &= np.hypot(x, y) <= cfg.annotate_range_m
    return inside


def _boxes(cfg: SyntheticConfig, actors: Actors):
    """Annotations (`_annotated` actors); and actor -> box index (-1: none)."""
    inside = _annotated(cfg, actors)
    box_of_actor = np.where(inside, np.cumsum(inside) - 1, -1)
    f32 = np.float32
    boxes = Boxes(actors.center[inside].astype(f32), actors.size[inside].astype(f32), actors.yaw[inside].astype(f32),
                  actors.velocity[inside].astype(f32), np.array(CLASSES, dtype="<U16")[actors.cls[inside]])
    return boxes, box_of_actor

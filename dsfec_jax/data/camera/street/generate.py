"""Frames and drives, deterministic from (config, split, index, seed).

Training samples are *independent scenes* (`generate_frame`, `StreetDataset`): frame i of split s
with seed k renders its own world (road, cross-section, clutter, traffic, light) at t = 0, drawn
from data/splits.split_rng(k, s, i), the rule both radar simulators follow. That is what a
detector needs: every sample a new street. Its GPS track holds the two fixes bracketing it
(t = 0 and 1 s), so the paper's interpolation applies to single frames too.

Drives (`generate_drive`) are sequences at `fps` along one world: the road curves, the ego keeps
its lane, road users move and keep their ids across frames, and the GPS track holds a fix every
1 / gps_hz s over the whole drive. Drive i of split s draws its world from
SeedSequence((k, s_id, i, 1)) and the sensor noise of its frame j from (k, s_id, i, 1, j + 1):
streams disjoint from the independent frames' and from each other's, and a frame can be made
without making the ones before it.

The splits are disjoint twice over: their random streams differ, and their worlds start in
separate squares of the ENU plane (world.split_area).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ....boxes.boxes2d import Boxes2D
from ....core.blas import single_threaded_blas
from ...splits import SPLITS, check_index, check_split, split_rng
from .camera import camera_rotation
from .config import StreetConfig
from .frame import StreetFrame, StreetObjects
from .geo import EgoPose, GpsTrack, enu_to_geodetic
from .labels import DROP_REASONS, label_objects
from .render import CameraPrims, raycast, shade_view, to_camera
from .world import Prims, World, sample_world

DRIVE_TAG = 1


class GroundMapper:
    """Camera-frame ground points (relative to the left camera) -> road (s, d)."""

    def __init__(self, world: World, cam_enu: np.ndarray, m: np.ndarray, s_ego: float, reach: float):
        self.road, self.m, self.origin = world.road, m, (float(cam_enu[0]), float(cam_enu[1]))
        self.section, self.crossings = world.road.section, world.crossings
        self.segments = world.road.segments_between(s_ego - 60.0, s_ego + reach)  # nothing further behind is in view

    def __call__(self, points: np.ndarray):
        enu = points @ self.m.astype(np.float32)  # M.T X for each row
        return self.road.locate(enu[:, 0], enu[:, 1], self.segments, self.origin)


def _finish(rgb: np.ndarray, look, rng: np.random.Generator | None) -> np.ndarray:
    img = rgb * np.float32(255.0 * look.exposure)
    if rng is not None and look.noise_sd > 0:
        img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(look.noise_sd)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def ego_pose(world: World, cfg: StreetConfig, t: float) -> EgoPose:
    e, n, heading, speed = world.ego_ground(t)
    lat, lon, alt = enu_to_geodetic(np.array([e, n, cfg.camera_height_m]), cfg.origin)
    return EgoPose(float(t), (e, n, cfg.camera_height_m), float(lat), float(lon), float(alt),
                   float(np.mod(heading, 2 * math.pi)), float(speed))


def gps_track(world: World, cfg: StreetConfig, times, rng: np.random.Generator | None = None) -> GpsTrack:
    """Fixes of the camera position at `times` (horizontal noise gps_noise_m, drawn from rng)."""
    times = np.asarray(times, np.float64)
    enu = np.array([ego_pose(world, cfg, t).enu for t in times], np.float64).reshape(-1, 3)
    if cfg.gps_noise_m > 0 and rng is not None:
        enu[:, :2] += cfg.gps_noise_m * rng.standard_normal((len(times), 2))
    return GpsTrack.from_enu(times, enu, cfg.origin)


def _visible_prims(world: World, cfg: StreetConfig, t: float, cam_enu: np.ndarray, m: np.ndarray):
    """The boxes within draw distance and not wholly behind the camera, and the actors' states."""
    def near(center, radius):
        rel = center - cam_enu
        return (rel @ m[2] > -radius) & (np.linalg.norm(rel[:, :2], axis=1) < cfg.draw_distance_m + radius)

    states = world.actor_states(t)
    keep = near(states["center"], states["size"].max(1, initial=0) if len(states["size"]) else np.zeros(0))
    static = world.static
    static = static.select(near(static.center, np.linalg.norm(static.half, axis=1)))
    return Prims.concat([static, world.actor_prims(t, keep)]), {k: v[keep] for k, v in states.items()}


def _actor_boxes(states: dict, cam_enu: np.ndarray, m: np.ndarray):
    """The actors' 3D boxes in the camera frame: centre, rot (columns along / left / up), half."""
    h = states["heading"]
    zero = np.zeros_like(h)
    axes = np.stack([np.stack([np.sin(h), np.cos(h), zero], 1), np.stack([-np.cos(h), np.sin(h), zero], 1),
                     np.stack([zero, zero, zero + 1], 1)], 2)
    size = states["size"]
    half = np.stack([size[:, 1], size[:, 0], size[:, 2]], 1) / 2
    return (states["center"] - cam_enu) @ m.T, np.einsum("ij,pjk->pik", m, axes), half


def render_frame(world: World, cfg: StreetConfig, t: float = 0.0, noise_rng: np.random.Generator | None = None,
                 gps: GpsTrack | None = None, frame_id: str = "", meta: dict | None = None) -> StreetFrame:
    """The frame the ego's camera takes of `world` at time t (noise_rng None: no sensor noise;
    gps None: the two exact fixes around t). Its small matrix products run on one BLAS thread
    (core/blas.py: OpenBLAS's pool only spins on them)."""
    with single_threaded_blas():
        return _render_frame(world, cfg, t, noise_rng, gps, frame_id, meta)


def _render_frame(world, cfg, t, noise_rng, gps, frame_id, meta) -> StreetFrame:
    cam = cfg.camera_model()
    if gps is None:
        first = math.floor(t * cfg.gps_hz) / cfg.gps_hz
        gps = gps_track(world, cfg, [first, first + 1 / cfg.gps_hz])
    pose = ego_pose(world, cfg, t)
    cam_enu = np.asarray(pose.enu, np.float64)
    m = camera_rotation(pose.heading_rad, math.radians(cfg.pitch_deg))
    prims, states = _visible_prims(world, cfg, t, cam_enu, m)
    cp: CameraPrims = to_camera(prims, cam_enu, m)
    up, h = m[:, 2], cfg.camera_height_m
    s_ego = world.ego.s + world.ego.speed * t
    mapper = GroundMapper(world, cam_enu, m, s_ego, cfg.draw_distance_m * 2)
    left = raycast(cp, cam, np.zeros(3), up, h, cfg.near_m, track_alone=True)
    image = _finish(shade_view(left, cp, cam, np.zeros(3), m, world.look, mapper), world.look, noise_rng)
    right = None
    if cfg.render_right:
        origin = np.array([cfg.baseline_m, 0.0, 0.0])
        hits = raycast(cp, cam, origin, up, h, cfg.near_m)
        right = _finish(shade_view(hits, cp, cam, origin, m, world.look, mapper), world.look, noise_rng)
    instances = np.where(left.prim >= 0, cp.owner[np.maximum(left.prim, 0)], -1).astype(np.int32) \
        if len(cp) else np.full(left.depth.shape, -1, np.int32)
    center_cam, rot, half = _actor_boxes(states, cam_enu, m)
    labels = label_objects(instances, left.alone, states["id"], center_cam, rot, half, cam, cfg)
    index = {int(i): k for k, i in enumerate(states["id"])}
    kept = labels.keep
    rows = np.array([index[int(i)] for i in labels.id[kept]], np.int64)
    objects = StreetObjects(labels.id[kept], center_cam[rows], states["center"][rows],
                            states["size"][rows].astype(np.float32), states["heading"][rows],
                            labels.visible_fraction[kept], labels.truncation[kept]) if len(rows) else StreetObjects.empty()
    names = states["name"][rows] if len(rows) else np.zeros(0, "<U16")
    boxes = Boxes2D(labels.xyxy[kept], names.astype("<U16"), None, labels.difficult[kept])
    meta = dict(meta or {})
    meta["dropped"] = {r: int(np.sum(labels.reason == r)) for r in DROP_REASONS}
    return StreetFrame(image, boxes, objects, left.depth, instances, right, cam, cfg.baseline_m, pose, gps,
                       frame_id, meta)


# ------------------------------------------------------------------------ frames and drives


def drive_rng(seed: int, split: str, index: int, *tags: int) -> np.random.Generator:
    check_split(split)
    if seed < 0 or index < 0:
        raise ValueError(f"seed={seed} and index={index} must be >= 0")
    return np.random.default_rng(np.random.SeedSequence((int(seed), SPLITS.index(split), int(index), DRIVE_TAG)
                                                        + tuple(int(t) for t in tags)))


def generate_frame(cfg: StreetConfig, split: str, index: int, seed: int = 0) -> StreetFrame:
    """Independent frame `index` of `split`: its own world, rendered at t = 0."""
    rng = split_rng(seed, split, index)
    world = sample_world(rng, cfg, SPLITS.index(split), 0.0, snapshot=True)
    gps = gps_track(world, cfg, [0.0, 1.0 / cfg.gps_hz], rng)
    meta = dict(split=split, index=int(index), seed=int(seed), drive=-1, frame=0)
    return render_frame(world, cfg, 0.0, rng, gps, f"street-{split}-s{seed}-{index:06d}", meta)


@dataclasses.dataclass(frozen=True)
class StreetDrive:
    world: World
    gps: GpsTrack
    times: np.ndarray        # (F,) frame times, s
    split: str
    index: int
    seed: int
    cfg: StreetConfig

    def __len__(self) -> int:
        return len(self.times)

    def frame(self, j: int) -> StreetFrame:
        j = check_index(j, len(self), "frame")
        meta = dict(split=self.split, index=int(self.index), seed=int(self.seed), drive=int(self.index), frame=j)
        return render_frame(self.world, self.cfg, float(self.times[j]), drive_rng(self.seed, self.split, self.index, j + 1),
                            self.gps, f"street-drive-{self.split}-s{self.seed}-{self.index:04d}-{j:04d}", meta)

    def __iter__(self):
        return (self.frame(j) for j in range(len(self)))

    def poses(self) -> list[EgoPose]:
        """The exact camera pose at every frame (no rendering)."""
        return [ego_pose(self.world, self.cfg, float(t)) for t in self.times]


def generate_drive(cfg: StreetConfig, split: str, index: int, seed: int = 0, num_frames: int = 100) -> StreetDrive:
    """Drive `index` of `split`: `num_frames` frames at cfg.fps along one world (rendered lazily)."""
    if num_frames < 1:
        raise ValueError(f"num_frames={num_frames} must be >= 1")
    duration = (num_frames - 1) / cfg.fps
    world = sample_world(drive_rng(seed, split, index), cfg, SPLITS.index(split), duration, snapshot=False)
    fixes = np.arange(int(math.ceil(duration * cfg.gps_hz - 1e-9)) + 1) / cfg.gps_hz
    gps = gps_track(world, cfg, fixes, drive_rng(seed, split, index, 0))
    return StreetDrive(world, gps, np.arange(num_frames) / cfg.fps, split, int(index), int(seed), cfg)


class StreetDataset:
    """`num_frames` independent frames of one split, generated on access (random access, no state)."""

    def __init__(self, cfg: StreetConfig | None = None, split: str = "train", seed: int = 0, num_frames: int = 1000):
        self.cfg, self.split = cfg or StreetConfig(), check_split(split)
        self.seed, self.num_frames = int(seed), int(num_frames)

    def __len__(self) -> int:
        return self.num_frames

    def __getitem__(self, index: int) -> StreetFrame:
        return generate_frame(self.cfg, self.split, check_index(index, self.num_frames, "frame"), self.seed)

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def __repr__(self):
        return f"StreetDataset({self.split!r}, seed={self.seed}, num_frames={self.num_frames})"

"""Named data sources -> frame sequences with the canonical class names, in the point columns asked for.

`--data synthetic` (default; the nuScenes-like ARS408 profile), `synthetic4d` (the VoD-like 4D
imaging-radar profile, `synthetic.radar4d_config`), `vod:PATH`, `tj4d:PATH`, `nuscenes:DATAROOT`.
Real sources are split deterministically by frame order (first 70 % train, next 15 % val, last
15 % test; `all` takes every frame) so their small samples can be used without a split file.

Point columns (`features=`): "dsfec" (default) maps every source onto DSFEC_FEATURES, the
nuScenes columns the DSFEC models read; "native" keeps a source's own columns (VoD: VOD_FEATURES,
TJ4D: TJ4D_FEATURES), what RadarNeXt reads. `synthetic4d` gives native VoD columns, or DSFEC's
with features="dsfec" (mapped as VoD's are). Either way box classes go through the source's class map
(`class_map`: KITTI_CLASS_MAP for VoD/TJ4D, CLASS_MAP otherwise); others are dropped.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

import numpy as np

from ...core.columns import NUSCENES_FEATURES
from .frame import Frame

DSFEC_FEATURES = NUSCENES_FEATURES  # the columns every source maps onto for DSFEC
# Dataset class names -> the heads' names. The canonical VRU name "bicycle" is a bicycle with its rider, as
# the synthetic benchmarks and nuScenes name it (CLASS_MAP keeps their names). VoD and TJ4D call that
# 'cyclist' (KITTI_CLASS_MAP); VoD's own 'bicycle' is one WITHOUT a rider (parked or pushed), which VoD's
# evaluation scores as no class at all (kitti_official_evaluate.clean_data: neither ground truth nor a
# neighbour of Cyclist, like 'rider' and 'bicycle_rack'), so it is dropped with them.
CLASS_MAP = {"bicycle": "bicycle", "car": "car", "truck": "truck", "pedestrian": "pedestrian"}
KITTI_CLASS_MAP = {"cyclist": "bicycle", "car": "car", "truck": "truck", "pedestrian": "pedestrian"}
SOURCE_CLASS_MAPS = {"vod": KITTI_CLASS_MAP, "tj4d": KITTI_CLASS_MAP}  # Frame.source -> its map
SPLIT_FRACTIONS = {"train": (0.0, 0.7), "val": (0.7, 0.85), "test": (0.85, 1.0), "all": (0.0, 1.0)}
FEATURE_SETS = ("dsfec", "native")
SOURCE_KINDS = ("synthetic", "synthetic4d", "vod:PATH", "tj4d:PATH", "nuscenes:DATAROOT")


def radial_components(frame: Frame, column: str) -> tuple[np.ndarray, np.ndarray]:
    """A radial speed as (vx, vy) along the line of sight: what nuScenes' vx_comp/vy_comp hold."""
    xy = frame.points[:, :2].astype(np.float64)
    r = np.maximum(np.linalg.norm(xy, axis=1), 1e-6)
    v = frame.column(column).astype(np.float64)
    return v * xy[:, 0] / r, v * xy[:, 1] / r


def to_dsfec_frame(frame: Frame) -> Frame:
    """Map a frame's own point columns onto the DSFEC features, and its classes onto the heads'.

    VoD: rcs <- RCS, radial v_r_comp -> (vx_comp, vy_comp), dt <- -time (VoD time is <= 0).
    TJ4D: rcs <- Power (dB SNR, the closest to an RCS it has), radial V_r -> (vx_comp, vy_comp)
    (TJ4D's V_r is not ego-compensated: an approximation), dt = 0.
    """
    if frame.point_features[: len(DSFEC_FEATURES)] == DSFEC_FEATURES:
        points = frame.points[:, : len(DSFEC_FEATURES)]
    else:
        names = frame.point_features
        n = len(frame.points)
        rcs = frame.column("rcs") if "rcs" in names else frame.column("power")
        radial = "v_r_comp" if "v_r_comp" in names else "v_r"
        vx, vy = radial_components(frame, radial)
        dt = -frame.column("time") if "time" in names else np.zeros(n)
        points = np.column_stack([frame.points[:, :3], rcs, vx, vy, dt]).astype(np.float32)
    return dataclasses.replace(canonical_classes(frame), points=points, point_features=DSFEC_FEATURES)


def class_map(source: str) -> dict[str, str]:
    """A source's class names -> the canonical ones (Frame.source: 'vod', 'tj4d', 'synthetic', ...)."""
    return SOURCE_CLASS_MAPS.get(source, CLASS_MAP)


def canonical_classes(frame: Frame) -> Frame:
    """The frame with its boxes renamed through its source's class map and the others dropped; points
    untouched. KITTI label rows in meta (their 2D boxes feed VoD's 40 px rule) stay aligned with the boxes."""
    mapping = class_map(frame.source)
    keep = np.isin(frame.boxes.names, list(mapping))
    boxes = frame.boxes.select(keep)
    boxes = dataclasses.replace(boxes, names=np.array([mapping[n] for n in boxes.names], dtype="<U16"))
    meta = frame.meta
    if "kitti_labels" in meta:
        meta = {**meta, "kitti_labels": meta["kitti_labels"].select(keep)}
    return dataclasses.replace(frame, boxes=boxes, meta=meta)


MAPPERS = {"dsfec": to_dsfec_frame, "native": canonical_classes}  # features= -> per-frame mapping


class MappedFrames:
    """A lazy sequence of frames with `mapper` (default `to_dsfec_frame`) applied on access."""

    def __init__(self, frames: Sequence[Frame], mapper=to_dsfec_frame):
        self.frames, self.mapper = frames, mapper

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, i: int) -> Frame:
        return self.mapper(self.frames[i])


def split_ids(ids: list[str], split: str) -> list[str]:
    if split not in SPLIT_FRACTIONS:
        raise ValueError(f"split={split!r}; expected one of {sorted(SPLIT_FRACTIONS)}")
    lo, hi = SPLIT_FRACTIONS[split]
    return ids[round(lo * len(ids)) : round(hi * len(ids))]


SYNTHETIC_FRAMES = 200  # frames a synthetic split generates when `frames` is None


class NoFrames(ValueError):
    """A source, split or count that yields no frames: an error, since any score of nothing is made up."""


def _take(ids: list[str], data: str, split: str, frames: int | None) -> list[str]:
    """The first `frames` ids of `split` (all of them for None); NoFrames when the split is empty."""
    chosen = split_ids(ids, split)[:frames]
    if not chosen:
        lo, hi = SPLIT_FRACTIONS[split]
        raise NoFrames(f"--data {data}: split {split!r} is empty: the source has {len(ids)} frames and the "
                       f"split takes {lo:.0%} to {hi:.0%} of them (try --split all)")
    return chosen


def load_frames(data: str, split: str, frames: int | None = None, seed: int = 0, difficulty: str = "normal",
                features: str = "dsfec"):
    """The frames of a source and split (synthetic: `frames` generated frames of that split, default
    SYNTHETIC_FRAMES; real sources: the first `frames` of the split, default all), with `features`
    point columns (see the module docstring). NoFrames for frames < 1 or an empty split."""
    if features not in FEATURE_SETS:
        raise ValueError(f"features={features!r}; expected one of {FEATURE_SETS}")
    if frames is not None and frames < 1:
        raise NoFrames(f"frames={frames}: expected a positive number of frames (or None for the source's default)")
    kind, _, path = data.partition(":")
    if kind in ("synthetic", "synthetic4d"):
        dataset = _synthetic(kind, split, frames, seed, difficulty)
        # a DSFEC model can read 4D frames too: their VoD columns map like VoD's own
        return MappedFrames(dataset, to_dsfec_frame) if kind == "synthetic4d" and features == "dsfec" else dataset
    if kind not in ("vod", "tj4d", "nuscenes"):
        raise ValueError(f"--data {data!r}: expected one of {', '.join(SOURCE_KINDS)}")
    if not path or not Path(path).exists():
        raise FileNotFoundError(f"--data {data}: expected {kind}:PATH with an existing path")
    mapper = MAPPERS[features]
    if kind in ("vod", "tj4d"):
        from .kitti import list_frames, read_tj4d_frame, read_vod_frame
        reader = read_vod_frame if kind == "vod" else read_tj4d_frame
        ids = _take(list_frames(path), data, split, frames)
        return MappedFrames([reader(path, i) for i in ids], mapper)
    from .nuscenes import NuScenesTables, list_samples, read_nuscenes_frame
    tables = NuScenesTables(path)
    tokens = _take(list_samples(tables), data, split, frames)
    return MappedFrames([read_nuscenes_frame(tables, t, nsweeps=6) for t in tokens], mapper)


def _synthetic(kind: str, split: str, frames: int | None, seed: int, difficulty: str):
    """Generated frames: the default profile's columns are DSFEC_FEATURES (its native ones),
    synthetic4d's are VoD's (mapped to DSFEC_FEATURES by the caller for features="dsfec")."""
    from .synthetic import SPLITS, SyntheticConfig, SyntheticDataset, radar4d_config
    if split not in SPLITS:
        raise ValueError(f"{kind} data has splits {SPLITS}, not {split!r}")
    cfg = SyntheticConfig(difficulty=difficulty) if kind == "synthetic" else radar4d_config(difficulty)
    return SyntheticDataset(cfg, split, seed, SYNTHETIC_FRAMES if frames is None else frames)

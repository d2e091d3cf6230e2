"""Named data sources -> frame sequences with the canonical class names, in the point columns asked for.

`--data synthetic` (default; the nuScenes-like ARS408 profile), `synthetic4d` (the VoD-like 4D
imaging-radar profile, `synthetic.radar4d_config`), `vod:PATH`, `tj4d:PATH`, `nuscenes:DATAROOT`.
Real sources are split deterministically by frame order (first 70 % train, next 15 % val, last
15 % test; `all` takes every frame) so their small samples can be used without a split file.

Point columns (`features=`): "dsfec" (default) maps every source onto DSFEC_FEATURES, the
nuScenes columns the DSFEC models read; "native" keeps a source's own columns (VoD: VOD_FEATURES,
TJ4D: TJ4D_FEATURES), what RadarNeXt reads. `synthetic4d` gives native VoD columns, or DSFEC's
with features="dsfec" (mapped as VoD's are). Either way box classes go through CLASS_MAP; others are dropped.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

import numpy as np

from .frame import Frame

DSFEC_FEATURES = ("x", "y", "z", "rcs", "vx_comp", "vy_comp", "dt")
# Dataset class names -> the DSFEC heads' names (VoD/TJ4D call a bicycle with rider 'cyclist').
CLASS_MAP = {"cyclist": "bicycle", "bicycle": "bicycle", "car": "car", "truck": "truck", "pedestrian": "pedestrian"}
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


def canonical_classes(frame: Frame) -> Frame:
    """The frame with its boxes renamed through CLASS_MAP and the others dropped; points untouched."""
    keep = np.isin(frame.boxes.names, list(CLASS_MAP))
    boxes = frame.boxes.select(keep)
    boxes = dataclasses.replace(boxes, names=np.array([CLASS_MAP[n] for n in boxes.names], dtype="<U16"))
    return dataclasses.replace(frame, boxes=boxes)


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


def load_frames(data: str, split: str, frames: int | None = None, seed: int = 0, difficulty: str = "normal",
                features: str = "dsfec"):
    """The frames of a source and split (synthetic: `frames` generated frames of that split),
    with `features` point columns (see the module docstring)."""
    if features not in FEATURE_SETS:
        raise ValueError(f"features={features!r}; expected one of {FEATURE_SETS}")
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
        ids = split_ids(list_frames(path), split)[: frames or None]
        return MappedFrames([reader(path, i) for i in ids], mapper)
    from .nuscenes import NuScenesTables, list_samples, read_nuscenes_frame
    tables = NuScenesTables(path)
    tokens = split_ids(list_samples(tables), split)[: frames or None]
    return MappedFrames([read_nuscenes_frame(tables, t, nsweeps=6) for t in tokens], mapper)


def _synthetic(kind: str, split: str, frames: int | None, seed: int, difficulty: str):
    """Generated frames: the default profile's columns are DSFEC_FEATURES (its native ones),
    synthetic4d's are VoD's (mapped to DSFEC_FEATURES by the caller for features="dsfec")."""
    from .synthetic import SPLITS, SyntheticConfig, SyntheticDataset, radar4d_config
    if split not in SPLITS:
        raise ValueError(f"{kind} data has splits {SPLITS}, not {split!r}")
    cfg = SyntheticConfig(difficulty=difficulty) if kind == "synthetic" else radar4d_config(difficulty)
    return SyntheticDataset(cfg, split, seed, frames or 200)

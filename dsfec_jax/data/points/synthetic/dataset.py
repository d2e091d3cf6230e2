"""Splits, determinism and the on-disk cache of the point-cloud simulator.

Frames follow data/splits.py: frame i of split s with seed k is a pure function of (config,
split, index, seed). Nothing is stored: `SyntheticDataset` generates on access.

Cache (`write_cache`, data/npz_cache.py): frame_000000.npz ... and, written last, manifest.json
(format "dsfec_jax.synthetic.frames", also listing the config's point_features); `CachedDataset`
checks it before reading. Each .npz holds points (N, F) float32, point_features,
box_center/size/yaw/velocity/names, frame_id, source, array-valued meta entries as `meta.<key>`,
and the other meta entries as JSON in `meta_json` (JSON lists come back as tuples).
"""

from __future__ import annotations

import numpy as np

from ...npz_cache import NpzCachedDataset, NpzCacheFormat, npz_bytes, npz_meta
from ...splits import SPLITS, check_index, check_split, split_rng  # noqa: F401 (SPLITS: exported here)
from ..frame import Boxes, Frame
from .config import FORMAT_VERSION, SyntheticConfig
from .simulate import simulate

frame_rng = split_rng  # the random stream of one frame: frame_rng(seed, split, index)


def generate_frame(cfg: SyntheticConfig, split: str, index: int, seed: int = 0) -> Frame:
    meta = dict(split=split, index=int(index), seed=int(seed))
    return simulate(frame_rng(seed, split, index), cfg, f"synthetic-{split}-s{seed}-{index:06d}", meta)


# Frames kept once generated: training reads every frame once an epoch, and simulating one costs
# the host time that on a 2-core machine the train step pays for (the rate and a frame's size:
# docs/points-data.md; `python -m dsfec_jax.data inspect --source synthetic` prints the rate).
KEPT_FRAMES = 4096


class SyntheticDataset:
    """`num_frames` frames of one split, generated on first access (random access); the first
    KEPT_FRAMES generated are kept, read-only, so a frame is simulated once however often it is read."""

    def __init__(self, cfg: SyntheticConfig | None = None, split: str = "train", seed: int = 0,
                 num_frames: int = 1000):
        self.cfg, self.split = cfg or SyntheticConfig(), check_split(split)
        self.seed, self.num_frames = int(seed), int(num_frames)
        self._kept: dict[int, Frame] = {}

    def __len__(self) -> int:
        return self.num_frames

    def __getitem__(self, index: int) -> Frame:
        index = check_index(index, self.num_frames, "frame")
        frame = self._kept.get(index)
        if frame is None:
            frame = read_only(generate_frame(self.cfg, self.split, index, self.seed))
            if len(self._kept) < KEPT_FRAMES:
                self._kept[index] = frame
        return frame

    def __getstate__(self) -> dict:  # a pickled dataset (to a Ray worker) regenerates its frames
        return {**self.__dict__, "_kept": {}}

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def __repr__(self):
        return f"SyntheticDataset({self.split!r}, seed={self.seed}, num_frames={self.num_frames}, {self.cfg.difficulty!r})"


def read_only(frame: Frame) -> Frame:
    """`frame` with its point and box arrays made read-only: a kept frame is shared by every
    reader, so one that changed it in place would change every later batch."""
    for array in (frame.points, frame.boxes.center, frame.boxes.size, frame.boxes.yaw, frame.boxes.velocity,
                  frame.boxes.names, frame.boxes.num_pts):
        if array is not None:
            array.flags.writeable = False
    return frame


# ------------------------------------------------------------------------------------- cache


def frame_to_npz_bytes(frame: Frame) -> bytes:
    b = frame.boxes
    return npz_bytes(dict(points=frame.points, point_features=np.array(frame.point_features),
                          frame_id=np.array(frame.frame_id), source=np.array(frame.source), box_center=b.center,
                          box_size=b.size, box_yaw=b.yaw, box_velocity=b.velocity,
                          box_names=b.names.astype("<U16")), frame.meta)


def frame_from_npz(z) -> Frame:
    """The frame of `frame_to_npz_bytes`; ValueError (or KeyError for a missing array) when damaged."""
    meta = {k: tuple(v) if isinstance(v, list) else v for k, v in npz_meta(z).items()}
    if z["point_features"].ndim != 1:
        raise ValueError("point_features must be a 1-D array of names")
    boxes = Boxes(z["box_center"], z["box_size"], z["box_yaw"], z["box_velocity"], z["box_names"])
    return Frame(z["points"], tuple(str(f) for f in z["point_features"]), boxes, str(z["frame_id"]),
                 str(z["source"]), meta)


FRAMES = NpzCacheFormat(
    name="dsfec_jax.synthetic.frames", version=FORMAT_VERSION, prefix="frame", noun="frame", item_title="frame",
    cache_title="a synthetic cache", encode=frame_to_npz_bytes, decode=frame_from_npz,
    config_type=SyntheticConfig, config_title="a SyntheticConfig",
    derived={"point_features": ("str_list", lambda cfg: list(cfg.point_features))})


class CachedDataset(NpzCachedDataset):
    """Frames read back from a `write_cache` directory; optionally checked against a config, split, seed."""

    FORMAT = FRAMES


write_cache = FRAMES.write  # (dataset, directory) -> directory: the frames, then manifest.json
read_manifest = FRAMES.read_manifest  # (directory) -> the checked manifest; ValueError naming file and field


def open_cache(directory, cfg: SyntheticConfig, split: str, seed: int, num_frames: int) -> CachedDataset:
    """The cache at `directory` if it holds exactly this dataset, else (re)build it first."""
    return CachedDataset.open(directory, SyntheticDataset(cfg, split, seed, num_frames))

"""Frames -> training batches (pillar tensors + head targets), as a pure function of the step.

Batch `s` of a run depends only on (seed, s): the frame order is a permutation per epoch drawn
from (seed, epoch) and augmentation draws from (seed, s). So a resumed run sees exactly the
batches an uninterrupted one would, with no iterator state to save.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from .augment import AugmentConfig, augment
from .frame import Frame
from .pillarize import PillarSpec, pillarize_frames
from .targets import detector_targets


def collate(frames: list[Frame], spec: PillarSpec, head_classes: dict, stride: int) -> dict:
    inputs, stats = pillarize_frames(frames, spec)
    targets = [detector_targets(f.boxes, head_classes, spec.grid, stride) for f in frames]
    return {"inputs": inputs, "targets": jax.tree.map(lambda *x: np.stack(x), *targets), "stats": stats}


class BatchStream:
    def __init__(self, frames: Sequence[Frame], spec: PillarSpec, head_classes: dict, stride: int,
                 batch_size: int, seed: int, augment_cfg: AugmentConfig | None = AugmentConfig()):
        if len(frames) < batch_size:
            raise ValueError(f"{len(frames)} training frames cannot fill a batch of {batch_size}")
        self.frames, self.spec, self.head_classes, self.stride = frames, spec, head_classes, stride
        self.batch_size, self.seed, self.augment_cfg = batch_size, seed, augment_cfg
        self.per_epoch = len(frames) // batch_size

    def indices(self, step: int) -> np.ndarray:
        epoch, pos = divmod(step, self.per_epoch)
        order = np.random.default_rng([self.seed, epoch]).permutation(len(self.frames))
        return order[pos * self.batch_size : (pos + 1) * self.batch_size]

    def batch(self, step: int) -> dict:
        rng = np.random.default_rng([self.seed, 1_000_003, step])
        frames = [self.frames[int(i)] for i in self.indices(step)]
        if self.augment_cfg is not None:
            frames = [augment(f, self.augment_cfg, rng) for f in frames]
        return collate(frames, self.spec, self.head_classes, self.stride)

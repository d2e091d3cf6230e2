"""Frames -> training batches (pillar tensors + the family's targets), as a pure function of the step.

The targets come from the detector's family (`targets_fn(boxes, grid)`, Family.targets): this
module only batches them, so it serves any head.

Batch `s` of a run depends only on (seed, s): the frame order is a permutation per epoch drawn
from (seed, epoch) and augmentation draws from (seed, s). So a resumed run sees exactly the
batches an uninterrupted one would, with no iterator state to save.

Training windows: a fully convolutional detector's weights do not depend on its grid, so it can
train on overlapping sub-windows of the grid (cycled per step) at a fraction of the cost and run
on the whole grid. Each window is a Grid of the same shape, so the network compiles once per
window. Windows are cycled per step (`window_sampling="cycle"`), or, with "objects", a step
takes a window that holds a box centre of its (augmented) frames with probability
OBJECT_WINDOW_SHARE, any window otherwise: on a sparse scene most windows are empty (TJ4D's cars
lie in 5 of its 25 windows, so 4 of 5 cycled steps teach nothing but background).
"""

from __future__ import annotations

from typing import Callable, Sequence

import jax
import numpy as np

from .points.augment import AugmentConfig, augment
from ..core.grid import Grid
from .points.frame import Boxes, Frame
from .points.pillarize import PillarSpec, pillarize_frames


TargetsFn = Callable[[Boxes, Grid], dict]
WINDOW_SAMPLING = ("cycle", "objects")
OBJECT_WINDOW_SHARE = 0.8  # the rest keeps empty windows in the mix: false alarms are learnt there


def collate(frames: list[Frame], spec: PillarSpec, targets_fn: TargetsFn, origin_input: bool = False) -> dict:
    """Pillar tensors and the stacked targets `targets_fn(boxes, grid)` of each frame.
    `origin_input` adds inputs['origin'], the window's (x_min, y_min) per sample, for networks
    that take it as a traced input."""
    inputs, stats = pillarize_frames(frames, spec)
    if origin_input:
        origin = np.array([spec.grid.x_range[0], spec.grid.y_range[0]], np.float32)
        inputs = {**inputs, "origin": np.tile(origin, (len(frames), 1))}
    targets = [targets_fn(f.boxes, spec.grid) for f in frames]
    return {"inputs": inputs, "targets": jax.tree.map(lambda *x: np.stack(x), *targets), "stats": stats}


def training_windows(grid: Grid, cells: int | None) -> list[Grid]:
    """Overlapping square windows of `cells` x `cells` covering `grid` (corners first); None or a
    size >= the grid gives the grid itself."""
    nx, ny = grid.shape
    if cells is None or (cells >= nx and cells >= ny):
        return [grid]
    span = cells * grid.cell

    def starts(lo, hi):  # the fewest evenly spaced windows that cover [lo, hi]
        n = int(np.ceil((hi - lo) / span - 1e-9))
        return np.linspace(lo, hi - span, n) if n > 1 else [lo]

    return [Grid((float(x), float(x + span)), (float(y), float(y + span)), grid.z_range, grid.cell)
            for x in starts(*grid.x_range) for y in starts(*grid.y_range)]


class BatchStream:
    """Batch `s`: frames of (seed, s) pillarized for window `window(s)` of `specs`."""

    def __init__(self, frames: Sequence[Frame], specs: list[PillarSpec] | PillarSpec, targets_fn: TargetsFn,
                 batch_size: int, seed: int, augment_cfg: AugmentConfig | None = AugmentConfig(),
                 origin_input: bool = False, window_sampling: str = "cycle"):
        if len(frames) < batch_size:
            raise ValueError(f"{len(frames)} training frames cannot fill a batch of {batch_size}")
        if window_sampling not in WINDOW_SAMPLING:
            raise ValueError(f"window_sampling must be one of {WINDOW_SAMPLING}, got {window_sampling!r}")
        self.window_sampling = window_sampling
        self.specs = specs if isinstance(specs, list) else [specs]
        self.frames = frames
        self.batch_size, self.seed, self.augment_cfg = batch_size, seed, augment_cfg
        self.targets_fn, self.origin_input = targets_fn, origin_input
        self.per_epoch = len(frames) // batch_size

    def indices(self, step: int) -> np.ndarray:
        epoch, pos = divmod(step, self.per_epoch)
        order = np.random.default_rng([self.seed, epoch]).permutation(len(self.frames))
        return order[pos * self.batch_size : (pos + 1) * self.batch_size]

    def window(self, step: int, frames: Sequence[Frame] = ()) -> int:
        """The window of step `step` whose batch holds `frames` (the augmented frames; "objects" only)."""
        if self.window_sampling == "cycle" or len(self.specs) == 1:
            return step % len(self.specs)
        rng = np.random.default_rng([self.seed, 2_000_003, step])
        occupied = [w for w, spec in enumerate(self.specs)
                    if any(spec.grid.contains(f.boxes.center[:, 0], f.boxes.center[:, 1]).any() for f in frames)]
        if occupied and rng.random() < OBJECT_WINDOW_SHARE:
            return int(occupied[rng.integers(len(occupied))])
        return int(rng.integers(len(self.specs)))

    def batch(self, step: int, rows: slice = slice(None)) -> dict:
        """Inputs, targets and pillarization stats of step `step`, and the index of its window;
        `rows`: only those rows of it (a process's share of a global batch: train/parallel.py).
        Every frame is augmented (one draw sequence per step, and the window may depend on all
        of them) but only the rows' frames are pillarized, which is where the time goes."""
        rng = np.random.default_rng([self.seed, 1_000_003, step])
        frames = [self.frames[int(i)] for i in self.indices(step)]
        if self.augment_cfg is not None:
            frames = [augment(f, self.augment_cfg, rng) for f in frames]
        window = self.window(step, frames)
        return {**collate(frames[rows], self.specs[window], self.targets_fn, self.origin_input), "window": window}

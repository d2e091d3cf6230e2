"""RD samples -> training batches of the YOLO-RD family, as a pure function of the step.

Batch `s` depends only on (seed, s), as data/batches.py's BatchStream: the sample order is a
permutation per epoch drawn from (seed, epoch) (the tail that does not fill a batch is skipped
that epoch), and sample i of batch s augments with its own generator from (seed, s, i). A
resumed run therefore sees exactly the batches an uninterrupted one would, with no iterator
state to save, and prefetching (data/prefetch.py) changes when a batch is built, never what.

Arrays (numpy; B = batch size, M = max_boxes, (H, W) the fitted input size):
  heat (B, H, W, 3) float32 and gray (B, H, W, 1) float32: representations.py's two inputs;
  gt_boxes (B, M, 4) float32: xyxy pixel edges in the fitted input (x = Doppler column, y = range
    row; moved by the augmentation and by fit='resize');
  gt_labels (B, M) int32: indices into `classes` (RD_CLASSES by default);
  gt_mask (B, M) bool: True for real boxes. Padding slots hold zero boxes and label 0 (the
    assigner clips labels and masks padding, models/yolo_rd/assigner.py), so only the mask tells.

M is fixed so the jitted step compiles once (ultralytics pads each batch to its own largest
count instead). A frame with more than M boxes keeps its M largest (area in the fitted input;
ties keep the earlier box), in their original order, logs a warning, and the batch counts the
dropped boxes in stats['dropped_boxes']: a long run should not die on one crowded frame, and the
count says when max_boxes is too small. The default 32 is four times the simulator's
max_objects (8): a box wrapped across the Doppler edge is two boxes, and a flip can split one.

`RDBatchStream.batch(step)` has BatchStream's layout, which train/loop.py and
profile/training.py read: {'inputs': {'heat', 'gray'}, 'targets': {'gt_boxes', 'gt_labels',
'gt_mask'}, 'window': 0, 'stats'}; `arrays(step)` is the same as one flat dict.
"""

from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from .augment import RDAugment, augment as augment_sample
from .classes import RD_CLASSES, class_index
from .representations import RDRepresentation, fitted_shape, representations
from .sample import RDSample

log = logging.getLogger(__name__)

DEFAULT_MAX_BOXES = 32
INPUT_KEYS = ("heat", "gray")
TARGET_KEYS = ("gt_boxes", "gt_labels", "gt_mask")
# Domain tags in the seeds: numpy's SeedSequence ignores trailing zeros ([k, e] and [k, e, 0] give
# the same stream, checked with numpy 2.4), so untagged (seed, epoch) and (seed, s, 0) would collide.
ORDER_TAG, AUGMENT_TAG = 0, 1


def padded_targets(sample: RDSample, rep: RDRepresentation, classes: Sequence[str],
                   max_boxes: int) -> tuple[dict, int]:
    """One sample's inputs and fixed-size targets (no batch axis) -> (arrays, boxes dropped)."""
    fitted = representations(sample, rep)
    boxes = fitted["boxes"]
    labels = np.array([class_index(str(n), tuple(classes)) for n in boxes.names], np.int32)
    keep = np.arange(len(boxes))
    if len(boxes) > max_boxes:
        area = np.prod(boxes.wh, axis=1)
        keep = np.sort(np.argsort(-area, kind="stable")[:max_boxes])
        log.warning("RD sample %r has %d boxes; kept the %d largest (raise max_boxes to keep all)",
                    sample.sample_id, len(boxes), max_boxes)
    gt_boxes = np.zeros((max_boxes, 4), np.float32)
    gt_labels = np.zeros((max_boxes,), np.int32)
    gt_mask = np.zeros((max_boxes,), bool)
    gt_boxes[: len(keep)] = boxes.xyxy[keep]
    gt_labels[: len(keep)] = labels[keep]
    gt_mask[: len(keep)] = True
    arrays = {"heat": fitted["heat"], "gray": fitted["gray"], "gt_boxes": gt_boxes, "gt_labels": gt_labels,
              "gt_mask": gt_mask}
    return arrays, len(boxes) - len(keep)


def stack(per_sample: list[dict]) -> dict:
    """Per-sample arrays -> batched arrays; ValueError when the fitted inputs differ in size."""
    shapes = {a["heat"].shape[:2] for a in per_sample}
    if len(shapes) > 1:
        raise ValueError(f"RD samples of one batch fit to different input sizes {sorted(shapes)}; give "
                         "RDRepresentation input_hw (fit='resize', or a minimum size with fit='pad')")
    return {k: np.stack([a[k] for a in per_sample]) for k in per_sample[0]}


class RDBatchStream:
    """Batch `step`: the samples of (seed, step), augmented, in both representations, padded to M boxes."""

    def __init__(self, samples: Sequence[RDSample], batch_size: int, seed: int,
                 augment: RDAugment | None = RDAugment(), representation: RDRepresentation = RDRepresentation(),
                 classes: Sequence[str] = RD_CLASSES, max_boxes: int = DEFAULT_MAX_BOXES):
        if batch_size < 1 or len(samples) < batch_size:
            raise ValueError(f"{len(samples)} training samples cannot fill a batch of {batch_size}")
        if max_boxes < 1:
            raise ValueError(f"max_boxes must be >= 1; got {max_boxes}")
        self.samples, self.batch_size, self.seed = samples, int(batch_size), int(seed)
        self.augment, self.representation = augment, representation
        self.classes, self.max_boxes = tuple(classes), int(max_boxes)
        self.per_epoch = len(samples) // self.batch_size

    def indices(self, step: int) -> np.ndarray:
        """The sample indices of batch `step`."""
        epoch, pos = divmod(int(step), self.per_epoch)
        order = np.random.default_rng([self.seed, ORDER_TAG, epoch]).permutation(len(self.samples))
        return order[pos * self.batch_size : (pos + 1) * self.batch_size]

    def sample(self, step: int, i: int) -> RDSample:
        """Sample i of batch `step`, augmented."""
        sample = self.samples[int(self.indices(step)[i])]
        if self.augment is None:
            return sample
        rng = np.random.default_rng(np.random.SeedSequence((self.seed, AUGMENT_TAG, int(step), i)))
        return augment_sample(sample, rng, self.augment)

    def arrays(self, step: int, rows: slice = slice(None)) -> dict:
        """Batch `step` (only its `rows`, where given) as one flat dict of the inputs and targets,
        plus 'dropped_boxes' (an int)."""
        per_sample, dropped = [], 0
        for i in range(self.batch_size)[rows]:
            arrays, n = padded_targets(self.sample(step, i), self.representation, self.classes, self.max_boxes)
            per_sample.append(arrays)
            dropped += n
        return {**stack(per_sample), "dropped_boxes": dropped}

    def batch(self, step: int, rows: slice = slice(None)) -> dict:
        """Batch `step` in BatchStream's layout (train/loop.py): inputs, targets, window 0, stats;
        `rows`: only those rows (each sample draws its own augmentation, so a slice is the same rows)."""
        arrays = self.arrays(step, rows)
        return {"inputs": {k: arrays[k] for k in INPUT_KEYS}, "targets": {k: arrays[k] for k in TARGET_KEYS},
                "window": 0, "stats": {"boxes": int(arrays["gt_mask"].sum()),
                                       "dropped_boxes": arrays["dropped_boxes"]}}


def rd_eval_inputs(sample: RDSample, representation: RDRepresentation = RDRepresentation(),
                   classes: Sequence[str] = RD_CLASSES, max_boxes: int = DEFAULT_MAX_BOXES) -> dict:
    """One sample (no augmentation) as a batch of 1 with the flat keys of `RDBatchStream.arrays`,
    plus 'to_map_scale' (1, 4) float32, (sx, sy, sx, sy) with map xyxy = fitted xyxy * scale,
    and 'map_hw' (1, 2) int32, the map's (range rows, Doppler columns): see `boxes_to_map`."""
    arrays, dropped = padded_targets(sample, representation, classes, max_boxes)
    h, w = sample.shape
    fh, fw = fitted_shape((h, w), representation)
    # fit='pad' leaves boxes where they are (scale 1); fit='resize' scaled them by (fw / w, fh / h).
    sx, sy = (1.0, 1.0) if representation.fit == "pad" else (w / fw, h / fh)
    return {**stack([arrays]), "dropped_boxes": dropped,
            "to_map_scale": np.array([[sx, sy, sx, sy]], np.float32), "map_hw": np.array([[h, w]], np.int32)}


def boxes_to_map(xyxy: np.ndarray, to_map_scale: np.ndarray, map_hw) -> np.ndarray:
    """Boxes (..., 4) xyxy in fitted-input pixels -> map pixels, clipped to the map (fit='pad'
    leaves a zero border that predictions may reach)."""
    h, w = (int(v) for v in np.ravel(map_hw))
    out = np.asarray(xyxy, np.float32) * np.ravel(to_map_scale).astype(np.float32)
    return np.clip(out, 0, np.array([w, h, w, h], np.float32))

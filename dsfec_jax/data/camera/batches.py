"""Camera images -> training batches of the camera family, as a pure function of the step.

Batch `s` depends only on (seed, s), as data/batches.py's BatchStream: the image order is a
permutation per epoch drawn from (seed, epoch) (the tail that does not fill a batch is skipped that
epoch), image i of batch s augments with its own generator from (seed, s, i), and the input size of
batch s comes from (seed, s // every). A resumed run sees exactly the batches of an uninterrupted
one, with no iterator state to save.

Multi-scale training (darknet's `random=1`: every 10 batches a new size, (rand() % 10 + 10) x 32,
i.e. 320..608 in steps of 32): `MultiScale.size(seed, step)` draws the long side of the input from
`sizes` once per block of `every` steps; the input is then `letterbox.network_shape(size, aspect)`
(416 -> 416 x 256 for the 16:9 street frames). The jitted train step is cached by input shape, so
each size compiles once and is reused whenever it comes back. darknet also pins the end of the run
to 608: at a switch, `if (get_current_batch(net)+200 > net->max_batches) dim = 608;`
(pjreddie/darknet examples/detector.c train_detector); `MultiScale(final_size=608)` with the run's
`total_steps` does the same (the `paper` profile; modalities/image/fit.py sets total_steps).

Arrays (numpy; B = batch size, M = max boxes, (H, W) = this step's input):
  image (B, H, W, 3) float32 in [0, 1]: the letterboxed, augmented images (the network's input);
  gt_boxes (B, M, 4) float32: xyxy pixel edges in the input; gt_labels (B, M) int32; gt_mask (B, M)
  bool: made by the family's `targets_fn(per-image Boxes2D) -> (arrays, dropped)`
  (modalities/image/fit.py hands in models/camera/targets.pad_batch with the model's classes: difficult boxes left out, as
  darknet's voc_label.py leaves them out of its labels), so this module never imports the models.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import numpy as np

from ...boxes.boxes2d import Boxes2D
from .augment import CameraAugment, augment as augment_image
from .images import CameraImage
from .letterbox import STRIDE, Affine, letterbox, network_shape, place_boxes, training_aspect, warp

TargetsFn = Callable[[list[Boxes2D]], tuple[dict, int]]
TARGET_KEYS = ("gt_boxes", "gt_labels", "gt_mask")
# Domain tags in the seeds (numpy's SeedSequence ignores trailing zeros: see data/rd/batches.py)
ORDER_TAG, AUGMENT_TAG, SIZE_TAG = 0, 1, 2
DARKNET_SIZES = tuple(range(320, 609, STRIDE))  # yolov3's random=1: 320, 352, ..., 608
DARKNET_EVERY = 10
DARKNET_FINAL_SIZE, DARKNET_FINAL_STEPS = 608, 200  # the run's last 200 batches at 608 (detector.c)


@dataclasses.dataclass(frozen=True)
class MultiScale:
    """The long side of the input: drawn from `sizes` for each block of `every` steps; with
    `final_size`, a block that starts less than `final_steps` before `total_steps` takes it."""
    sizes: tuple[int, ...] = (416,)
    every: int = DARKNET_EVERY
    final_size: int | None = None
    final_steps: int = DARKNET_FINAL_STEPS
    total_steps: int | None = None

    def __post_init__(self):
        sizes = self.sizes + ((self.final_size,) if self.final_size is not None else ())
        if not self.sizes or any(int(s) % STRIDE or int(s) < STRIDE for s in sizes) or self.every < 1:
            raise ValueError(f"MultiScale: sizes must be positive multiples of {STRIDE} and every >= 1; got {self}")

    def record(self) -> dict:
        """What a run records: sizes and every, and the final-size rule where there is one."""
        out = {"sizes": [int(s) for s in self.sizes], "every": self.every}
        if self.final_size is not None:
            out.update(final_size=self.final_size, final_steps=self.final_steps, total_steps=self.total_steps)
        return out

    @classmethod
    def span(cls, low: int, high: int, every: int = DARKNET_EVERY) -> "MultiScale":
        """Every multiple of 32 from `low` to `high`."""
        return cls(tuple(range(low, high + 1, STRIDE)), every)

    def size(self, seed: int, step: int) -> int:
        block_start = int(step) // self.every * self.every
        if self.final_size is not None and self.total_steps is not None \
                and block_start + self.final_steps > self.total_steps:
            return int(self.final_size)
        if len(self.sizes) == 1:
            return int(self.sizes[0])
        rng = np.random.default_rng([int(seed), SIZE_TAG, int(step) // self.every])
        return int(self.sizes[rng.integers(len(self.sizes))])


def image_shapes(images: Sequence[CameraImage]) -> list[tuple[int, int]]:
    """(h, w) of every image, without loading the lazy sources' pixels where they know it."""
    known = getattr(images, "shapes", None)
    return list(known()) if known is not None else [images[i].hw for i in range(len(images))]


def eval_input(item: CameraImage, input_hw) -> tuple[np.ndarray, Affine]:
    """One image letterboxed into `input_hw` (no augmentation) -> (float32 (H, W, 3) in [0, 1], the
    image -> input map, whose `inverse` takes predicted boxes back to the image)."""
    affine = letterbox(item.hw, input_hw)
    return warp(item.image, affine, input_hw).astype(np.float32) / 255.0, affine


class CameraBatchStream:
    """Batch `step`: the images of (seed, step), augmented, letterboxed into this step's input size."""

    def __init__(self, images: Sequence[CameraImage], batch_size: int, seed: int, targets_fn: TargetsFn,
                 augment: CameraAugment | None = CameraAugment(), sizes: MultiScale = MultiScale(),
                 aspect: float | None = None):
        if batch_size < 1 or len(images) < batch_size:
            raise ValueError(f"{len(images)} training images cannot fill a batch of {batch_size}")
        self.images, self.batch_size, self.seed = images, int(batch_size), int(seed)
        self.targets_fn, self.augment, self.sizes = targets_fn, augment, sizes
        self.aspect = training_aspect(image_shapes(images)) if aspect is None else float(aspect)
        self.per_epoch = len(images) // self.batch_size

    def indices(self, step: int) -> np.ndarray:
        """The image indices of batch `step`."""
        epoch, pos = divmod(int(step), self.per_epoch)
        order = np.random.default_rng([self.seed, ORDER_TAG, epoch]).permutation(len(self.images))
        return order[pos * self.batch_size : (pos + 1) * self.batch_size]

    def input_hw(self, step: int) -> tuple[int, int]:
        """(H, W) of batch `step`'s input."""
        return network_shape(self.sizes.size(self.seed, step), self.aspect)

    def sample(self, step: int, i: int) -> tuple[np.ndarray, Boxes2D]:
        """Image i of batch `step` in its input: (uint8 (H, W, 3), boxes in input pixels)."""
        item = self.images[int(self.indices(step)[i])]
        hw = self.input_hw(step)
        if self.augment is None:
            affine = letterbox(item.hw, hw)
            return warp(item.image, affine, hw), place_boxes(item.boxes, affine, hw)
        rng = np.random.default_rng(np.random.SeedSequence((self.seed, AUGMENT_TAG, int(step), i)))
        return augment_image(item, hw, rng, self.augment)

    def batch(self, step: int, rows: slice = slice(None)) -> dict:
        """Batch `step` in BatchStream's layout (train/loop.py): inputs, targets, window 0, stats;
        `rows`: only those rows (each image draws its own augmentation, so a slice is the same rows)."""
        images, boxes = zip(*(self.sample(step, i) for i in range(self.batch_size)[rows]))
        targets, dropped = self.targets_fn(list(boxes))
        return {"inputs": {"image": np.stack(images).astype(np.float32) / 255.0},
                "targets": {k: targets[k] for k in TARGET_KEYS}, "window": 0,
                "stats": {"boxes": int(targets["gt_mask"].sum()), "dropped_boxes": int(dropped),
                          "input_hw": list(self.input_hw(step))}}

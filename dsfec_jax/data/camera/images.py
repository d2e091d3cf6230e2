"""One camera image with its ground truth: what the camera family trains on, predicts and is scored on,
whichever source it comes from (a street frame, a VOC image).

- image: (H, W, 3) uint8 RGB, as the file or the renderer gives it (any size: the batches and the
  predictor letterbox it into the network's input).
- boxes: Boxes2D in this image's pixels (edges), class names in the source's own vocabulary, and
  `difficult` flags (VOC's; the street benchmark's occlusion / truncation / size rules): training
  leaves difficult boxes out of the targets, the metrics neither reward nor penalise them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...boxes.boxes2d import Boxes2D


@dataclasses.dataclass(frozen=True)
class CameraImage:
    image_id: str
    image: np.ndarray
    boxes: Boxes2D

    def __post_init__(self):
        if self.image.ndim != 3 or self.image.shape[-1] != 3 or self.image.dtype != np.uint8:
            raise ValueError(f"CameraImage {self.image_id!r}: image {self.image.shape} {self.image.dtype}; "
                             "expected (H, W, 3) uint8 RGB")
        if self.boxes.scores is not None:
            raise ValueError(f"CameraImage {self.image_id!r}: ground-truth boxes must have scores=None")

    @property
    def hw(self) -> tuple[int, int]:
        return int(self.image.shape[0]), int(self.image.shape[1])

    @property
    def difficult(self) -> np.ndarray:
        flags = self.boxes.difficult
        return np.zeros(len(self.boxes), bool) if flags is None else np.asarray(flags, bool)

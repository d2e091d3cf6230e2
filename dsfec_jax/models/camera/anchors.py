"""YOLOv3's anchor boxes as data: nine (width, height) priors in input pixels and the three that
each output scale uses (darknet's `mask`).

Facts from pjreddie/darknet cfg/yolov3-voc.cfg (every [yolo] section lists all nine anchors and
picks three with `mask`): anchors 10,13 16,30 33,23 | 30,61 62,45 59,119 | 116,90 156,198 373,326;
the first [yolo] layer (stride 32) has mask 6,7,8, the second (16) 3,4,5, the third (8) 0,1,2.
The networks here return their outputs ordered by stride (8, 16, 32), so `masks[s]` is the mask
of output s. Anchor k of output s is anchor `masks[s][k]` of the nine; each output is
(B, H/stride, W/stride, len(mask), 5 + C).
"""

from __future__ import annotations

import dataclasses

import numpy as np

YOLOV3_SIZES = ((10.0, 13.0), (16.0, 30.0), (33.0, 23.0),
                (30.0, 61.0), (62.0, 45.0), (59.0, 119.0),
                (116.0, 90.0), (156.0, 198.0), (373.0, 326.0))
YOLOV3_MASKS = ((0, 1, 2), (3, 4, 5), (6, 7, 8))
YOLOV3_STRIDES = (8, 16, 32)


@dataclasses.dataclass(frozen=True)
class Anchors:
    """All anchors (width, height) in input pixels, the mask and the stride of every output scale.
    Hashable, so it can be a static argument of a jitted function."""
    sizes: tuple[tuple[float, float], ...] = YOLOV3_SIZES
    masks: tuple[tuple[int, ...], ...] = YOLOV3_MASKS
    strides: tuple[int, ...] = YOLOV3_STRIDES

    def __post_init__(self):
        if len(self.masks) != len(self.strides):
            raise ValueError(f"{len(self.masks)} masks for {len(self.strides)} strides")
        used = sorted(k for mask in self.masks for k in mask)
        if used != list(range(len(self.sizes))):
            raise ValueError(f"the masks {self.masks} must use each of the {len(self.sizes)} anchors once")
        if len({len(m) for m in self.masks}) != 1:
            raise ValueError(f"every scale needs the same number of anchors; masks {self.masks}")

    @property
    def per_scale(self) -> int:
        return len(self.masks[0])

    def array(self) -> np.ndarray:
        """(len(sizes), 2) float32 (width, height) in input pixels."""
        return np.asarray(self.sizes, np.float32)

    def for_scale(self, s: int) -> np.ndarray:
        """(per_scale, 2) float32: the anchors of output s, in mask order."""
        return self.array()[list(self.masks[s])]


YOLOV3_ANCHORS = Anchors()

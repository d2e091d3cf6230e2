"""Where an image lands in the network's input: the input size for an image's shape, the letterbox,
and one affine warp that carries the image and its boxes together.

Resize policy (training, evaluation, prediction): letterbox, as darknet evaluates YOLOv3
(validate_detector's LETTERBOX_DATA): the image scaled by one factor until its long side fills the
input, centred, grey (127) around it, so no object is stretched. The input is rectangular: its
long side is the asked size, its short side the letterboxed image's short side rounded up to a
multiple of 32 (`network_shape`, ultralytics' "rect" inference). The street frames (416 x 234,
16:9) go into 416 x 256 inputs: 38 % fewer pixels than 416 x 416, 9 % grey, nothing distorted. A
set of images of mixed shapes (VOC) trains on square inputs (`training_aspect`); each image is
evaluated at its own rectangle (one compile per distinct input shape).

Coordinates are pixel edges (boxes/boxes2d.py): an `Affine` maps image x to input x = sx x + ox
(and y alike; sx < 0 mirrors), the same map for every pixel edge and every box edge, so a box
drawn around an object's pixels stays around them after the warp. The warp samples bilinearly with
Pillow's affine transform (its pixel centres sit at +0.5, as the edge convention needs).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...boxes.boxes2d import Boxes2D

STRIDE = 32  # the networks' largest stride: input sides are multiples of it
FILL = 127   # grey around the letterboxed image (darknet's 0.5, ultralytics' 114)


@dataclasses.dataclass(frozen=True)
class Affine:
    """input = (sx x + ox, sy y + oy) for image pixel coordinates (x, y)."""
    sx: float
    sy: float
    ox: float
    oy: float

    def then(self, other: "Affine") -> "Affine":
        """This map followed by `other`."""
        return Affine(other.sx * self.sx, other.sy * self.sy, other.sx * self.ox + other.ox,
                      other.sy * self.oy + other.oy)

    def boxes(self, xyxy) -> np.ndarray:
        """(K, 4) xyxy -> mapped xyxy, corners re-ordered where the map mirrors."""
        xyxy = np.asarray(xyxy, np.float64).reshape(-1, 4)
        xs = xyxy[:, [0, 2]] * self.sx + self.ox
        ys = xyxy[:, [1, 3]] * self.sy + self.oy
        return np.column_stack([xs.min(1), ys.min(1), xs.max(1), ys.max(1)])

    def inverse(self, xyxy) -> np.ndarray:
        """Input-pixel boxes -> image pixels (no clipping)."""
        inv = Affine(1 / self.sx, 1 / self.sy, -self.ox / self.sx, -self.oy / self.sy)
        return inv.boxes(xyxy)


def round_up(value: float, multiple: int = STRIDE) -> int:
    return max(multiple, int(math.ceil(value / multiple - 1e-9)) * multiple)


def network_shape(size: int, aspect: float) -> tuple[int, int]:
    """(H, W) of the input for images of height / width `aspect`: the long side `size`, the short
    side the letterboxed image's, rounded up to a multiple of 32."""
    if size % STRIDE:
        raise ValueError(f"input size {size} is not a multiple of {STRIDE}")
    if aspect <= 1:
        return min(size, round_up(size * aspect)), size
    return size, min(size, round_up(size / aspect))


def training_aspect(shapes) -> float:
    """The aspect a training set's inputs share: its images' height / width when they all have one
    shape (the street benchmark), else 1 (square inputs for mixed shapes, VOC)."""
    distinct = {tuple(s) for s in shapes}
    if len(distinct) == 1:
        h, w = distinct.pop()
        return h / w
    return 1.0


def letterbox(image_hw, input_hw) -> Affine:
    """The letterbox map: one scale so the image fits the input, centred."""
    (h, w), (net_h, net_w) = image_hw, input_hw
    r = min(net_w / w, net_h / h)
    return Affine(r, r, (net_w - w * r) / 2, (net_h - h * r) / 2)


def warp(image: np.ndarray, affine: Affine, input_hw, fill: int = FILL) -> np.ndarray:
    """(h, w, 3) uint8 -> (H, W, 3) uint8: the image placed by `affine`, `fill` where it does not reach."""
    from PIL import Image

    inv = Affine(1 / affine.sx, 1 / affine.sy, -affine.ox / affine.sx, -affine.oy / affine.sy)
    out = Image.fromarray(image).transform((int(input_hw[1]), int(input_hw[0])), Image.Transform.AFFINE,
                                           (inv.sx, 0.0, inv.ox, 0.0, inv.sy, inv.oy),
                                           resample=Image.Resampling.BILINEAR, fillcolor=(fill,) * 3)
    return np.asarray(out)


def place_boxes(boxes: Boxes2D, affine: Affine, input_hw, min_side: float = 0.0,
                min_kept: float = 0.0) -> Boxes2D:
    """Ground truth moved by `affine` and clipped to the input; a box is dropped when a clipped side
    is below `min_side` pixels or less than `min_kept` of its moved area stays inside."""
    if not len(boxes):
        return boxes
    moved = affine.boxes(boxes.xyxy)
    h, w = input_hw
    clipped = np.clip(moved, 0, [w, h, w, h])
    side = clipped[:, 2:] - clipped[:, :2]
    area = np.prod(moved[:, 2:] - moved[:, :2], 1)
    keep = (side.min(1) >= min_side) & (np.prod(side, 1) >= min_kept * area) & (side.min(1) > 0)
    kept = boxes.select(keep)
    return dataclasses.replace(kept, xyxy=clipped[keep].astype(np.float32))

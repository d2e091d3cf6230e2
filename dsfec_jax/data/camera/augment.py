"""The augmentations YOLOv3 users expect, drawn from one generator per image (reproducible).

- HSV jitter, darknet's (src/image.c random_distort_image, yolov3-voc.cfg hue .1, saturation 1.5,
  exposure 1.5): hue shifted by U(-hue, hue) of the colour circle; saturation and value scaled by
  darknet's rand_scale(s): U(1, s), inverted with probability 1/2. Boxes are untouched.
- Random scale and translate on top of the letterbox (ultralytics' random_perspective without
  rotation or shear, milder): the placed image scaled by U(1 - scale, 1 + scale) about the input's
  centre and shifted by U(-translate, translate) of the input's width and height; the uncovered
  input is grey (letterbox.FILL).
- Horizontal flip with probability `flip`.
The geometric part is one affine (letterbox.Affine), applied to the image by one warp and to the
boxes exactly; boxes are clipped to the input and dropped when a clipped side is under `min_side`
pixels or under `min_kept` of the box stays inside (ultralytics' box_candidates: 2 px, 0.1 of the
area; 0.2 here, since a pedestrian cut to a fifth is no longer a pedestrian's shape).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...boxes.boxes2d import Boxes2D
from .images import CameraImage
from .letterbox import Affine, letterbox, place_boxes, warp


@dataclasses.dataclass(frozen=True)
class CameraAugment:
    flip: float = 0.5        # probability of a horizontal flip
    scale: float = 0.25      # placed image scaled by U(1 - scale, 1 + scale)
    translate: float = 0.1   # shifted by U(-t, t) of the input's sides
    hue: float = 0.1         # darknet's hue: a fraction of the colour circle
    saturation: float = 1.5  # darknet's rand_scale bounds
    exposure: float = 1.5
    min_side: float = 2.0    # pixels, after clipping
    min_kept: float = 0.2    # of a box's area, after clipping

    def __post_init__(self):
        if not (0 <= self.flip <= 1 and 0 <= self.scale < 1 and 0 <= self.translate < 1 and 0 <= self.hue <= 0.5
                and self.saturation >= 1 and self.exposure >= 1 and self.min_side >= 0 and 0 <= self.min_kept <= 1):
            raise ValueError(f"CameraAugment: flip in [0, 1], scale and translate in [0, 1), hue in [0, 0.5], "
                             f"saturation and exposure >= 1, min_side >= 0, min_kept in [0, 1]; got {self}")


def rand_scale(rng: np.random.Generator, s: float) -> float:
    """darknet's rand_scale: U(1, s), inverted with probability 1/2."""
    scale = rng.uniform(1.0, s)
    return scale if rng.random() < 0.5 else 1.0 / scale


def hsv_jitter(image: np.ndarray, hue_shift: float, sat_scale: float, val_scale: float) -> np.ndarray:
    """(H, W, 3) uint8 RGB with its hue shifted (a fraction of the circle) and S, V scaled (Pillow's
    8-bit HSV, lookup tables)."""
    from PIL import Image

    h, s, v = Image.fromarray(image).convert("HSV").split()
    levels = np.arange(256, dtype=np.float64)
    h = h.point((np.rint(levels + hue_shift * 256) % 256).astype(np.uint8).tolist())
    s = s.point(np.clip(np.rint(levels * sat_scale), 0, 255).astype(np.uint8).tolist())
    v = v.point(np.clip(np.rint(levels * val_scale), 0, 255).astype(np.uint8).tolist())
    return np.asarray(Image.merge("HSV", (h, s, v)).convert("RGB"))


def jitter(base: Affine, input_hw, rng: np.random.Generator, cfg: CameraAugment) -> Affine:
    """`base` followed by a random scale about the input's centre, a shift and maybe a mirror."""
    h, w = input_hw
    s = rng.uniform(1 - cfg.scale, 1 + cfg.scale)
    tx, ty = rng.uniform(-cfg.translate, cfg.translate, 2) * (w, h)
    out = base.then(Affine(s, s, (1 - s) * w / 2 + tx, (1 - s) * h / 2 + ty))
    if rng.random() < cfg.flip:
        out = out.then(Affine(-1.0, 1.0, float(w), 0.0))
    return out


def augment(item: CameraImage, input_hw, rng: np.random.Generator,
            cfg: CameraAugment = CameraAugment()) -> tuple[np.ndarray, Boxes2D]:
    """One random augmentation of `item` placed in an input of `input_hw` -> (uint8 (H, W, 3) input,
    its boxes in input pixels). The draws come from `rng` only, in a fixed order."""
    hue = rng.uniform(-cfg.hue, cfg.hue)
    sat, val = rand_scale(rng, cfg.saturation), rand_scale(rng, cfg.exposure)
    affine = jitter(letterbox(item.hw, input_hw), input_hw, rng, cfg)
    image = hsv_jitter(item.image, hue, sat, val)  # on the source image: fewer pixels than the input
    return warp(image, affine, input_hw), place_boxes(item.boxes, affine, input_hw, cfg.min_side, cfg.min_kept)

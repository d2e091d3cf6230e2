"""Axis-aligned 2D boxes in image pixel coordinates: what image-like detectors (range-Doppler maps,
camera images) output and their datasets label.

Convention (the COCO one): x runs along columns, y along rows, and (x1, y1, x2, y2) are pixel
*edges*, so a box covering columns c0..c1 and rows r0..r1 inclusive is (c0, r0, c1 + 1, r1 + 1) and
its width is x2 - x1. No "+1" in areas or IoU (pycocotools and DAROD compute them the same way).
PASCAL VOC's 1-based inclusive (xmin, ymin, xmax, ymax) is (xmin - 1, ymin - 1, xmax, ymax) here
(data/camera/voc.py), which turns voc_eval's "+1" widths into plain x2 - x1.

`difficult` marks ground truth that a protocol may neither reward nor penalise (VOC's "difficult"
objects, an occluded object of a synthetic scene); None means no box is difficult. It travels with
the boxes so that select() and every reader keep it aligned with them.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Boxes2D:
    xyxy: np.ndarray                 # (K, 4) float32, (x1, y1, x2, y2) pixel edges, x1 <= x2, y1 <= y2
    names: np.ndarray                # (K,) str class names
    scores: np.ndarray | None = None  # (K,) float32 for detections; None for ground truth
    difficult: np.ndarray | None = None  # (K,) bool for ground truth; None: no box is difficult

    def __post_init__(self):
        k = len(self.names)
        if np.shape(self.xyxy) != (k, 4):
            raise ValueError(f"Boxes2D.xyxy has shape {np.shape(self.xyxy)}; expected {(k, 4)}")
        if self.scores is not None and np.shape(self.scores) != (k,):
            raise ValueError(f"Boxes2D.scores has shape {np.shape(self.scores)}; expected {(k,)} or None")
        flags = self.difficult
        if flags is not None and (np.shape(flags) != (k,) or np.asarray(flags).dtype != bool):
            raise ValueError(f"Boxes2D.difficult must be None or a ({k},) bool array; got shape "
                             f"{np.shape(flags)}, dtype {np.asarray(flags).dtype}")
        if k and not (np.all(self.xyxy[:, 2] >= self.xyxy[:, 0]) and np.all(self.xyxy[:, 3] >= self.xyxy[:, 1])):
            raise ValueError("Boxes2D.xyxy must have x1 <= x2 and y1 <= y2 in every row")

    def __len__(self) -> int:
        return len(self.names)

    @classmethod
    def empty(cls, with_scores: bool = False) -> "Boxes2D":
        return cls(np.zeros((0, 4), np.float32), np.zeros((0,), "<U16"),
                   np.zeros((0,), np.float32) if with_scores else None)

    def select(self, keep) -> "Boxes2D":
        return Boxes2D(self.xyxy[keep], self.names[keep], None if self.scores is None else self.scores[keep],
                       None if self.difficult is None else self.difficult[keep])

    @property
    def wh(self) -> np.ndarray:
        return self.xyxy[:, 2:] - self.xyxy[:, :2]


def xyxy_to_xywh(xyxy: np.ndarray) -> np.ndarray:
    """(x1, y1, x2, y2) -> (x, y, w, h), COCO's bbox layout."""
    xyxy = np.asarray(xyxy, np.float64)
    return np.concatenate([xyxy[..., :2], xyxy[..., 2:] - xyxy[..., :2]], -1)


def xywh_to_xyxy(xywh: np.ndarray) -> np.ndarray:
    xywh = np.asarray(xywh, np.float64)
    return np.concatenate([xywh[..., :2], xywh[..., :2] + xywh[..., 2:]], -1)


def pairwise_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every box in a (N, 4) with every box in b (M, 4), xyxy pixel edges -> (N, M) float64.
    Empty boxes have IoU 0 with everything (no division by zero)."""
    a, b = np.asarray(a, np.float64).reshape(-1, 4), np.asarray(b, np.float64).reshape(-1, 4)
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), -1)
    area_a = np.prod(np.clip(a[:, 2:] - a[:, :2], 0, None), -1)
    area_b = np.prod(np.clip(b[:, 2:] - b[:, :2], 0, None), -1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)

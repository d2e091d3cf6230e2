"""From the rendered object-id mask to labels: visible boxes, visible fraction, truncation, and the
drop / difficult rules of config.py (its docstring states them)."""

from __future__ import annotations

import dataclasses

import numpy as np

from .camera import PinholeCamera
from .config import StreetConfig
from .render import projected_extent

DROP_REASONS = ("occluded", "tiny")


@dataclasses.dataclass(frozen=True)
class ObjectLabels:
    """Per object that covers >= 1 pixel rendered alone (kept and dropped), aligned arrays."""

    id: np.ndarray                 # (K,) int32 actor id
    xyxy: np.ndarray               # (K, 4) float32 visible extent, pixel edges (zeros when invisible)
    visible_pixels: np.ndarray     # (K,) int64
    alone_pixels: np.ndarray       # (K,) int64
    truncation: np.ndarray         # (K,) float32
    keep: np.ndarray               # (K,) bool
    difficult: np.ndarray          # (K,) bool
    reason: np.ndarray             # (K,) '<U8': '' kept, else one of DROP_REASONS

    @property
    def visible_fraction(self) -> np.ndarray:
        return (self.visible_pixels / np.maximum(self.alone_pixels, 1)).astype(np.float32)


def mask_extents(instances: np.ndarray) -> dict[int, tuple[int, tuple[int, int, int, int]]]:
    """id -> (pixel count, (x1, y1, x2, y2) pixel edges) of every id >= 0 in an (H, W) mask."""
    r, c = np.nonzero(instances >= 0)
    if not len(r):
        return {}
    ids = instances[r, c]
    order = np.argsort(ids, kind="stable")
    ids, r, c = ids[order], r[order], c[order]
    uniq, start, counts = np.unique(ids, return_index=True, return_counts=True)
    rmin, rmax = np.minimum.reduceat(r, start), np.maximum.reduceat(r, start)
    cmin, cmax = np.minimum.reduceat(c, start), np.maximum.reduceat(c, start)
    return {int(i): (int(n), (int(c0), int(r0), int(c1) + 1, int(r1) + 1))
            for i, n, r0, r1, c0, c1 in zip(uniq, counts, rmin, rmax, cmin, cmax)}


def truncation(extent: np.ndarray, cam: PinholeCamera) -> np.ndarray:
    """Share of each projected 2D box (B, 4 continuous, NaN: behind the camera) outside the frame."""
    x1, y1, x2, y2 = extent.T
    area = (x2 - x1) * (y2 - y1)
    inside = (np.clip(np.minimum(x2, cam.width) - np.maximum(x1, 0), 0, None)
              * np.clip(np.minimum(y2, cam.height) - np.maximum(y1, 0), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = 1 - inside / area
    return np.where(np.isfinite(out) & (area > 0), np.clip(out, 0, 1), 1.0).astype(np.float32)


def label_objects(instances: np.ndarray, alone: dict, ids: np.ndarray, center_cam: np.ndarray,
                  rot: np.ndarray, half: np.ndarray, cam: PinholeCamera, cfg: StreetConfig) -> ObjectLabels:
    """Labels of the objects `ids` (their 3D boxes in the camera frame: center, rot, half) given the
    visible-object mask `instances` and the alone pixel counts."""
    extents = mask_extents(instances)
    trunc_all = truncation(projected_extent(center_cam, rot, half, cam, cfg.near_m), cam)
    rows = []
    for i, oid in enumerate(ids):
        n_alone = alone.get(int(oid), 0)
        if n_alone == 0:
            continue
        n_vis, box = extents.get(int(oid), (0, (0, 0, 0, 0)))
        frac = n_vis / n_alone
        height = box[3] - box[1]
        if frac < cfg.min_visible_fraction or n_vis == 0:
            reason = "occluded"
        elif n_vis < cfg.min_visible_pixels or height < cfg.min_box_height_px:
            reason = "tiny"
        else:
            reason = ""
        difficult = bool(reason == "" and (frac < cfg.difficult_visible_fraction or trunc_all[i] > cfg.difficult_truncation
                                           or height < cfg.difficult_box_height_px))
        rows.append((int(oid), box, n_vis, n_alone, trunc_all[i], reason == "", difficult, reason))
    if not rows:
        return ObjectLabels(np.zeros(0, np.int32), np.zeros((0, 4), np.float32), np.zeros(0, np.int64),
                            np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros(0, bool), np.zeros(0, bool),
                            np.zeros(0, "<U8"))
    oid, box, n_vis, n_alone, trunc, keep, difficult, reason = zip(*rows)
    return ObjectLabels(np.array(oid, np.int32), np.array(box, np.float32), np.array(n_vis, np.int64),
                        np.array(n_alone, np.int64), np.array(trunc, np.float32), np.array(keep, bool),
                        np.array(difficult, bool), np.array(reason, "<U8"))

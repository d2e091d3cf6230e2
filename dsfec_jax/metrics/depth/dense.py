"""Dense depth metrics of Eigen et al. 2014 as monodepth computes them (mrharicot/monodepth
utils/evaluation_utils.py compute_errors, utils/evaluate_kitti.py).

Per image: the predicted depth is clipped to [min_depth, max_depth] (monodepth: 1e-3 and 80 m);
the pixels scored are those whose ground truth is finite and min_depth < gt < max_depth (the sky,
+inf in the street benchmark, and anything beyond the cap are left out); then
    abs_rel  = mean |gt - pred| / gt          sq_rel = mean (gt - pred)**2 / gt
    rmse     = sqrt(mean (gt - pred)**2)      rmse_log = sqrt(mean (log gt - log pred)**2)
    a_k      = share of pixels with max(gt / pred, pred / gt) < 1.25**k, k = 1, 2, 3
A set of images scores the mean of its per-image metrics (monodepth's average over the test
files), not the metrics of all pixels pooled. Depths in metres, rmse in metres.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

METRICS = ("abs_rel", "sq_rel", "rmse", "rmse_log", "a1", "a2", "a3")
MIN_DEPTH, MAX_DEPTH = 1e-3, 80.0   # evaluate_kitti.py defaults


def valid_mask(gt: np.ndarray, min_depth: float = MIN_DEPTH, max_depth: float = MAX_DEPTH) -> np.ndarray:
    """The pixels scored: finite ground truth strictly inside (min_depth, max_depth)."""
    gt = np.asarray(gt, np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(gt) & (gt > min_depth) & (gt < max_depth)


def compute_errors(gt: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """The seven metrics of matched 1-D arrays of positive depths (compute_errors)."""
    gt, pred = np.asarray(gt, np.float64), np.asarray(pred, np.float64)
    if gt.shape != pred.shape or gt.size == 0:
        raise ValueError(f"compute_errors: need matched non-empty depths, got {gt.shape} and {pred.shape}")
    thresh = np.maximum(gt / pred, pred / gt)
    return {"abs_rel": float(np.mean(np.abs(gt - pred) / gt)),
            "sq_rel": float(np.mean((gt - pred) ** 2 / gt)),
            "rmse": float(np.sqrt(np.mean((gt - pred) ** 2))),
            "rmse_log": float(np.sqrt(np.mean((np.log(gt) - np.log(pred)) ** 2))),
            **{f"a{k}": float(np.mean(thresh < 1.25 ** k)) for k in (1, 2, 3)}}


def depth_errors(gt_depth: np.ndarray, pred_depth: np.ndarray, min_depth: float = MIN_DEPTH,
                 max_depth: float = MAX_DEPTH) -> dict[str, float]:
    """One image's metrics: (H, W) ground-truth and predicted depths in metres. The prediction is
    clipped to the cap (a non-finite one, e.g. from zero disparity, counts as max_depth); adds
    'pixels', the number of pixels scored. ValueError when the shapes differ or none is valid."""
    gt, pred = np.asarray(gt_depth, np.float64), np.asarray(pred_depth, np.float64)
    if gt.shape != pred.shape:
        raise ValueError(f"depth_errors: ground truth {gt.shape} and prediction {pred.shape} differ in shape")
    if not min_depth < max_depth:
        raise ValueError(f"depth_errors: min_depth={min_depth} must be below max_depth={max_depth}")
    mask = valid_mask(gt, min_depth, max_depth)
    if not mask.any():
        raise ValueError(f"depth_errors: no ground-truth pixel is finite and within ({min_depth}, {max_depth}) m")
    pred = np.clip(np.nan_to_num(pred, nan=max_depth, posinf=max_depth, neginf=min_depth), min_depth, max_depth)
    return {**compute_errors(gt[mask], pred[mask]), "pixels": int(mask.sum())}


def mean_errors(rows: Iterable[dict]) -> dict[str, float]:
    """The mean of per-image metrics (the figure monodepth reports), with 'images' and 'pixels'."""
    rows = list(rows)
    if not rows:
        raise ValueError("mean_errors: no images")
    return {**{m: float(np.mean([r[m] for r in rows])) for m in METRICS}, "images": len(rows),
            "pixels": int(sum(r.get("pixels", 0) for r in rows))}

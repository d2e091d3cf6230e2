"""Depth error per detection against ground truth, by range bin of the true depth.

The paper claims the distance error stays under 5 % within 40 m (shuffle_yolov3_edge.txt §5;
§4: "around 5%"); this table is what that claim is checked against. Inputs are matched 1-D
arrays, one entry per detection: the depth the pipeline estimated for it and the true depth of
the same thing (the caller chooses which: the ground-truth depth map at the same reference pixel
isolates the depth estimator; the object centre's depth also charges the reference point's
geometry). Depths are metres along the optical axis.

Bins are [lo, hi) of the *true* depth, RANGE_BINS_M = 0-10, 10-20, 20-40, 40+ m, plus the row
"0-40" (the paper's claim) and "all". Per bin: count; `invalid`, the detections without a usable
estimate (NaN, inf, <= 0: a window of sky, zero disparity), which are counted but not scored;
over the valid ones, the mean and median absolute relative error |pred - true| / true in %, the
RMSE in metres, and the share (%) within 5 % relative error.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

RANGE_BINS_M = (0.0, 10.0, 20.0, 40.0, math.inf)
CLAIM_PCT, CLAIM_RANGE_M = 5.0, 40.0   # the paper's: under 5 % within 40 m


def bin_label(lo: float, hi: float) -> str:
    return f"{lo:g}-{hi:g}" if math.isfinite(hi) else f"{lo:g}+"


def range_rows(true_range_m, bins=RANGE_BINS_M) -> list[tuple[str, np.ndarray]]:
    """(label, mask) per bin [lo, hi) of `true_range_m`, then "0-40" (up to CLAIM_RANGE_M) and "all"
    (every finite range, also one below the first edge: an object beside or behind the camera)."""
    r = np.asarray(true_range_m, np.float64)
    if list(bins) != sorted(bins) or len(bins) < 2:
        raise ValueError(f"range bins must be increasing edges; got {bins}")
    rows = [(bin_label(lo, hi), (r >= lo) & (r < hi)) for lo, hi in zip(bins[:-1], bins[1:])]
    return rows + [(bin_label(bins[0], CLAIM_RANGE_M), (r >= bins[0]) & (r < CLAIM_RANGE_M)),
                   ("all", np.isfinite(r))]


@dataclasses.dataclass(frozen=True)
class DepthErrorRow:
    range_m: str
    count: int
    invalid: int
    mean_rel_pct: float
    median_rel_pct: float
    rmse_m: float
    within_5pct: float   # share of the valid detections, %

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def depth_error_table(pred_m, true_m, bins=RANGE_BINS_M) -> list[DepthErrorRow]:
    """One row per range bin (module docstring); NaN statistics for a bin with no valid detection."""
    pred, true = np.asarray(pred_m, np.float64).reshape(-1), np.asarray(true_m, np.float64).reshape(-1)
    if pred.shape != true.shape:
        raise ValueError(f"{pred.size} estimated depths for {true.size} true depths; expected one each per detection")
    if np.any(~np.isfinite(true) | (true <= 0)):
        raise ValueError("true depths must be finite and > 0 (a detection without ground truth is not scored)")
    valid = np.isfinite(pred) & (pred > 0)
    rel = np.abs(pred - true) / true * 100.0
    rows = []
    for label, mask in range_rows(true, bins):
        v = mask & valid
        n = int(v.sum())
        stats = (float(rel[v].mean()), float(np.median(rel[v])), float(np.sqrt(np.mean((pred[v] - true[v]) ** 2))),
                 float(np.mean(rel[v] <= CLAIM_PCT) * 100.0)) if n else (math.nan,) * 4
        rows.append(DepthErrorRow(label, int(mask.sum()), int((mask & ~valid).sum()), *stats))
    return rows


def format_depth_table(rows: list[DepthErrorRow]) -> str:
    """A Markdown table of the rows, with the paper's claim beside the 0-40 m row."""
    lines = ["| true depth (m) | detections | no estimate | mean rel. err. (%) | median (%) | RMSE (m) "
             "| within 5 % (%) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        note = " (paper: < 5 % error)" if r.range_m == bin_label(0.0, CLAIM_RANGE_M) else ""
        lines.append(f"| {r.range_m}{note} | {r.count} | {r.invalid} | {r.mean_rel_pct:.2f} | {r.median_rel_pct:.2f} | "
                     f"{r.rmse_m:.2f} | {r.within_5pct:.1f} |")
    return "\n".join(lines) + "\n"

"""The nuScenes AP on resampled evaluation sets, for bootstrap confidence intervals.

A prediction's match in the devkit's greedy matching depends only on the ground truth and the
higher-scored predictions *of its own sample*, so whether it is a true positive does not change when
other samples are added, dropped or repeated. A `MatchTable` keeps, for one class, every prediction's
sample, score and hit flag at each threshold, plus the ground-truth count per sample; from it the AP of
any multiset of the samples (a bootstrap resample) follows exactly, without matching again: repeat each
prediction as often as its sample is drawn (copies stay adjacent in score order) and rebuild the
precision curve. With every sample drawn once it is `nuscenes.evaluate`'s AP to the last bit.

The same table holds a COCO class (metrics.boxes2d.coco_matches: `kind` "coco", IoU thresholds, images
as samples); `table_ap` scores either kind with its own AP.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from . import nuscenes
from .boxes2d.coco_matches import resampled_coco_ap
from .match_table import MatchTable


def match_table(gt: Mapping, pred: Mapping, class_name: str, dist_ths: Sequence[float] = nuscenes.DIST_THS,
                **filters) -> MatchTable:
    """Match one class as `nuscenes.evaluate` does (same filters, same `filters` keywords) and keep the
    per-prediction outcome."""
    gt, pred = nuscenes.prepare(gt, pred, **filters)
    cc = nuscenes.class_candidates(gt, pred, class_name, max(dist_ths))
    samples = tuple(gt)
    index = {tok: i for i, tok in enumerate(samples)}
    npos = np.array([len(cc.gts.get(tok, [])) for tok in samples], np.int64)
    sample_of = np.array([index[tok] for tok, _ in cc.preds], np.int64)
    scores = np.array([b["detection_score"] for _, b in cc.preds], float)
    is_tp = np.stack([nuscenes.greedy_match(cc, class_name, float(th))[0] for th in dist_ths]).astype(bool) \
        if cc.preds else np.zeros((len(dist_ths), 0), bool)
    return MatchTable(class_name, samples, npos, sample_of, scores, tuple(float(t) for t in dist_ths), is_tp)


def resampled_ap(table: MatchTable, counts: np.ndarray | None = None) -> np.ndarray:
    """(T,) AP at each threshold on the multiset where sample s appears counts[s] times (default: once)."""
    counts = np.ones(len(table.samples), np.int64) if counts is None else np.asarray(counts, np.int64)
    if counts.shape != (len(table.samples),):
        raise ValueError(f"counts has shape {counts.shape}; the table has {len(table.samples)} samples")
    npos = int(counts @ table.npos)
    if table.kind != "nuscenes":
        raise ValueError(f"resampled_ap scores nuScenes tables; this one is {table.kind!r} (use table_ap)")
    out = np.zeros(len(table.thresholds))
    if npos == 0:
        return out  # the devkit's no_predictions: AP 0
    rows = np.repeat(np.arange(len(table.scores)), counts[table.sample_of])
    recall_points = np.linspace(0, 1, nuscenes.NELEM)
    for t in range(len(table.thresholds)):
        hits = table.is_tp[t, rows]
        if not hits.any():
            continue
        tp = np.cumsum(hits)
        fp = np.cumsum(~hits)
        precision = np.interp(recall_points, tp / float(npos), tp / (fp + tp), right=0)
        out[t] = nuscenes.ap_of_precision(precision)
    return out


def table_ap(table: MatchTable, counts: np.ndarray | None = None, columns: Sequence[int] | None = None) -> np.ndarray:
    """(T,) AP at each threshold on a resampled set, with the AP of the table's kind: nuScenes' (0
    without ground truth) or COCO's (NaN without ground truth, as COCOeval's -1). `columns`: the
    thresholds the caller reads (COCO computes only those, NaN elsewhere; nuScenes' four are cheap)."""
    if table.kind == "coco":
        return resampled_coco_ap(table, counts, columns)
    return resampled_ap(table, counts)


def bootstrap_counts(n_samples: int, resamples: int, seed: int = 0) -> np.ndarray:
    """(resamples, n_samples) draw counts: each row a bootstrap resample of the samples (with replacement)."""
    rng = np.random.default_rng(seed)
    return rng.multinomial(n_samples, np.full(n_samples, 1.0 / n_samples), size=resamples)

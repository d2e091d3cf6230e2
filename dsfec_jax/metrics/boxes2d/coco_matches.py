"""COCO AP of 2D boxes on resampled image sets, for bootstrap intervals over evaluation frames.

COCOeval matches every (image, class) on its own (evaluateImg), so whether a detection hits at an
IoU threshold does not change when other images are added, dropped or repeated. `match_tables`
reads COCOeval's per-image results into one `match_table.MatchTable` per class (kind "coco": the
detections in accumulate's order, their hit flags at each IoU threshold, the non-ignored ground
truth per image), and `resampled_coco_ap` redoes accumulate's 101-point interpolated precision on
any multiset of the images: repeat each detection as often as its image is drawn (copies stay
adjacent in score order) and rebuild the curve. With every image drawn once it is COCOeval's
per-class AP (pycocotools stays the reference; this only replays its accumulate step).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..match_table import MatchTable

# COCOeval.Params.recThrs: 0:.01:1
RECALL_POINTS = np.linspace(0.0, 1.00, int(np.round((1.00 - 0.0) / 0.01)) + 1, endpoint=True)


def _class_table(evaluator, k: int, name: str, samples: tuple[str, ...]) -> MatchTable:
    """Class k of an evaluated COCOeval at area 'all' and its largest maxDets, as accumulate reads it."""
    params = evaluator.params
    n_images, max_det = len(params.imgIds), params.maxDets[-1]
    start = k * len(params.areaRng) * n_images  # evalImgs is [class][area][image]; area index 0: 'all'
    entries = evaluator.evalImgs[start:start + n_images]
    npos = np.zeros(n_images, np.int64)
    scores, sample_of, matched, ignored = [], [], [], []
    for i, e in enumerate(entries):
        if e is None:  # neither ground truth nor detections of this class in image i
            continue
        npos[i] = int(np.count_nonzero(np.asarray(e["gtIgnore"]) == 0))
        d = np.asarray(e["dtScores"][:max_det], np.float64)
        scores.append(d)
        sample_of.append(np.full(len(d), i, np.int64))
        matched.append(np.asarray(e["dtMatches"])[:, :max_det] != 0)
        ignored.append(np.asarray(e["dtIgnore"], bool)[:, :max_det])
    n_thr = len(params.iouThrs)
    if scores:
        scores_all = np.concatenate(scores)
        order = np.argsort(-scores_all, kind="mergesort")  # accumulate's order, ties by image order
        scores_all, sample_all = scores_all[order], np.concatenate(sample_of)[order]
        is_tp = np.concatenate(matched, axis=1)[:, order]
        ign = np.concatenate(ignored, axis=1)[:, order]
    else:
        scores_all, sample_all = np.zeros(0), np.zeros(0, np.int64)
        is_tp, ign = np.zeros((n_thr, 0), bool), np.zeros((n_thr, 0), bool)
    # an ignored detection counts neither as hit nor as miss; one table row per detection needs the
    # same verdict at every threshold (always so without crowd boxes and with area 'all')
    mixed = ign.any(0) & ~ign.all(0)
    if mixed.any():
        raise ValueError(f"class {name!r}: {int(mixed.sum())} detection(s) ignored at some IoU thresholds only "
                         "(crowd ground truth?); a match table cannot hold them")
    keep = ~ign.any(0)
    return MatchTable(name, samples, npos, sample_all[keep], scores_all[keep],
                      tuple(float(t) for t in params.iouThrs), is_tp[:, keep], kind="coco")


def match_tables(evaluator, category_names: Mapping[int, str], image_samples: Mapping[int, str],
                 classes: Sequence[str] | None = None) -> dict[str, MatchTable]:
    """{class name: MatchTable} of an evaluated (evaluate()d) COCOeval; `category_names` and
    `image_samples` map COCO ids back to class names and sample ids; `classes` picks (default all)."""
    samples = tuple(image_samples[i] for i in evaluator.params.imgIds)
    names = [category_names[c] for c in evaluator.params.catIds]
    unknown = sorted(set(classes or ()) - set(names))
    if unknown:
        raise ValueError(f"match tables asked for classes {unknown}; the evaluation has {names}")
    return {name: _class_table(evaluator, k, name, samples) for k, name in enumerate(names)
            if classes is None or name in classes}


def _interpolated_ap(hits: np.ndarray, npos: int) -> float:
    """accumulate's precision at the 101 recall points (right-to-left envelope), averaged."""
    tp = np.cumsum(hits).astype(float)
    fp = np.cumsum(~hits).astype(float)
    q = np.zeros(len(RECALL_POINTS))
    if len(tp):
        recall = tp / npos
        precision = np.maximum.accumulate((tp / (fp + tp + np.spacing(1)))[::-1])[::-1]
        at = np.searchsorted(recall, RECALL_POINTS, side="left")
        valid = at < len(tp)
        q[valid] = precision[at[valid]]
    return float(np.mean(q))


def resampled_coco_ap(table: MatchTable, counts: np.ndarray | None = None,
                      columns: Sequence[int] | None = None) -> np.ndarray:
    """(T,) COCO AP at each IoU threshold (or only at `columns`, NaN elsewhere) on the multiset where
    image s appears counts[s] times (default once); NaN where the draw holds no ground truth."""
    if table.kind != "coco":
        raise ValueError(f"resampled_coco_ap scores COCO tables; this one is {table.kind!r}")
    counts = np.ones(len(table.samples), np.int64) if counts is None else np.asarray(counts, np.int64)
    if counts.shape != (len(table.samples),):
        raise ValueError(f"counts has shape {counts.shape}; the table has {len(table.samples)} images")
    out = np.full(len(table.thresholds), np.nan)
    npos = int(counts @ table.npos)
    if npos == 0:
        return out
    rows = np.repeat(np.arange(len(table.scores)), counts[table.sample_of])
    for t in range(len(table.thresholds)) if columns is None else columns:
        out[t] = _interpolated_ap(table.is_tp[t, rows], npos)
    return out

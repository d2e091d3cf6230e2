"""COCO AP of 2D boxes, computed by pycocotools' COCOeval: the reference implementation, which this
project calls and does not rewrite. The boxes go through the project's COCO conversion
(metrics.boxes2d.coco_json), so what is scored is exactly what a COCO file would hold.

Returned: mAP@[.5:.95], AP50, AP75, AP@30, AP@70, per-class AP@[.5:.95] and AP50, and COCOeval's
12 standard stats (AP, AP50, AP75, APs, APm, APl, AR1, AR10, AR100, ARs, ARm, ARl).

AP@30 is not one of COCOeval's thresholds (0.50:0.05:0.95). COCOeval matches every threshold
independently (cocoeval.py evaluateImg loops over iouThrs), so one run with 0.3 added in front
gives the standard thresholds' results unchanged plus a column for 0.3; AP@30 is read from
eval['precision'] there as COCOeval's own summary reads any column (area 'all', 100 detections,
mean over the recall points and categories that have ground truth). The 0.3 column is then
removed and COCOeval.summarize() runs on the 10 standard columns, so mAP@[.5:.95] and the 12
stats average exactly the standard thresholds. AP@70 is a standard column.

With `match_classes`, the result also carries those classes' per-image matches
(match_table.MatchTable, kind "coco") for bootstrap intervals over the evaluated images.

pycocotools conventions kept: an undefined number (no ground truth) is -1 in `stats`; the named
fields turn it into NaN. A class without ground truth has per-class AP NaN. pycocotools' prints
are silenced.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
from collections.abc import Mapping, Sequence

import numpy as np

from ...boxes.boxes2d import Boxes2D
from ..match_table import MatchTable
from . import coco_matches
from .coco_json import CocoGroundTruth, coco_dets_to_list, coco_gt_to_dict, default_category_ids, default_image_ids

COCO_IOU_THRESHOLDS = np.linspace(0.5, 0.95, int(np.round((0.95 - 0.5) / 0.05)) + 1, endpoint=True)  # as Params
EXTRA_IOU_THRESHOLDS = (0.3,)
STAT_NAMES = ("AP", "AP50", "AP75", "APs", "APm", "APl", "AR1", "AR10", "AR100", "ARs", "ARm", "ARl")


@dataclasses.dataclass(frozen=True)
class CocoMetrics:
    map: float                     # AP@[.5:.95] (COCO's "AP")
    ap50: float
    ap75: float
    ap30: float
    ap70: float
    per_class_ap: dict[str, float]     # AP@[.5:.95] per class name; NaN without ground truth
    per_class_ap50: dict[str, float]
    stats: tuple[float, ...]           # COCOeval.stats, in STAT_NAMES order (-1 where undefined)
    match_tables: dict[str, MatchTable] = dataclasses.field(default_factory=dict)  # of `match_classes`

    def as_dict(self) -> dict[str, float]:
        out = {"mAP@[.5:.95]": self.map, "AP50": self.ap50, "AP75": self.ap75, "AP30": self.ap30, "AP70": self.ap70}
        out.update({f"coco/{name}": value for name, value in zip(STAT_NAMES, self.stats)})
        out.update({f"AP/{name}": value for name, value in self.per_class_ap.items()})
        out.update({f"AP50/{name}": value for name, value in self.per_class_ap50.items()})
        return out


def _mean_defined(precision: np.ndarray) -> float:
    """COCOeval's summary of a precision slice: mean over entries > -1, -1 -> NaN when none."""
    defined = precision[precision > -1]
    return float(np.mean(defined)) if defined.size else math.nan


def _column(thresholds: np.ndarray, iou: float) -> int:
    return int(np.flatnonzero(np.isclose(thresholds, iou, rtol=0, atol=1e-12))[0])


def _cocoeval(gt_dict: dict, results: list[dict]):
    """COCOeval (bbox) evaluated and accumulated at the standard thresholds plus the extra ones."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO()
        coco_gt.dataset = gt_dict
        coco_gt.createIndex()
        if results:
            coco_dt = coco_gt.loadRes(results)
        else:  # loadRes cannot take an empty list (it reads results[0]); an empty result set is this
            coco_dt = COCO()
            coco_dt.dataset = {"images": list(gt_dict["images"]), "categories": list(gt_dict["categories"]),
                               "annotations": []}
            coco_dt.createIndex()
        evaluator = COCOeval(coco_gt, coco_dt, "bbox")
        evaluator.params.iouThrs = np.concatenate([np.asarray(EXTRA_IOU_THRESHOLDS, np.float64), COCO_IOU_THRESHOLDS])
        evaluator.evaluate()
        evaluator.accumulate()
    return evaluator


def _standard_summary(evaluator) -> tuple[float, ...]:
    """COCOeval.summarize() on the 10 standard threshold columns only."""
    keep = len(EXTRA_IOU_THRESHOLDS)
    evaluator.params.iouThrs = COCO_IOU_THRESHOLDS
    evaluator.eval = dict(evaluator.eval, precision=evaluator.eval["precision"][keep:],
                          recall=evaluator.eval["recall"][keep:])
    with contextlib.redirect_stdout(io.StringIO()):
        evaluator.summarize()
    return tuple(float(s) for s in evaluator.stats)


def coco_evaluate(gts: Mapping[str, Boxes2D] | CocoGroundTruth, dets: Mapping[str, Boxes2D],
                  classes: Sequence[str] | None = None, *, image_ids: Mapping[str, int] | None = None,
                  category_ids: Mapping[str, int] | None = None, areas: Mapping[str, np.ndarray] | None = None,
                  iscrowd: Mapping[str, np.ndarray] | None = None,
                  match_classes: Sequence[str] = ()) -> CocoMetrics:
    """COCO AP of detections (sample id -> Boxes2D with scores) against ground truth (sample id ->
    Boxes2D, every scored frame, empty ones included), through COCO JSON and pycocotools.

    `gts` may be a CocoGroundTruth (read from a file): its classes, ids, areas and iscrowd are used.
    Otherwise classes are required; image and category ids default as in coco_json."""
    if isinstance(gts, CocoGroundTruth):
        classes = gts.classes if classes is None else classes
        image_ids, category_ids = image_ids or gts.image_ids, category_ids or gts.category_ids
        areas, iscrowd, gts = areas or gts.areas, iscrowd or gts.iscrowd, gts.boxes
    if classes is None:
        raise ValueError("coco_evaluate needs the class names (classes=...)")
    image_ids = image_ids or default_image_ids(list(gts))
    category_ids = category_ids or default_category_ids(classes)
    gt_dict = coco_gt_to_dict(gts, classes, image_ids=image_ids, category_ids=category_ids, areas=areas,
                              iscrowd=iscrowd)
    results = coco_dets_to_list(dets, category_ids, image_ids)
    evaluator = _cocoeval(gt_dict, results)
    thresholds = evaluator.params.iouThrs
    precision = evaluator.eval["precision"][..., 0, -1]     # (T, R, K) at area 'all', maxDets 100
    standard = [_column(thresholds, t) for t in COCO_IOU_THRESHOLDS]
    names = {cid: name for name, cid in category_ids.items()}
    cat_names = [names[c] for c in evaluator.params.catIds]
    ap = {t: _mean_defined(precision[_column(thresholds, t)]) for t in (0.3, 0.5, 0.7, 0.75)}
    per_class = {n: _mean_defined(precision[standard][:, :, k]) for k, n in enumerate(cat_names)}
    per_class50 = {n: _mean_defined(precision[_column(thresholds, 0.5), :, k]) for k, n in enumerate(cat_names)}
    tables = {} if not match_classes else coco_matches.match_tables(
        evaluator, names, {i: sample for sample, i in image_ids.items()}, match_classes)
    stats = _standard_summary(evaluator)  # after the tables: it trims the evaluator's threshold columns
    return CocoMetrics(map=_mean_defined(precision[standard]), ap50=ap[0.5], ap75=ap[0.75], ap30=ap[0.3],
                       ap70=ap[0.7], per_class_ap=per_class, per_class_ap50=per_class50, stats=stats,
                       match_tables=tables)

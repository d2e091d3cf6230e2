"""Score detections on range-Doppler maps: COCO AP through pycocotools (the paper's mAP@30, @50 and
@50-95, per class) and the DAROD protocol beside it, in percent, on the maps' pixel boxes.

The two protocols differ (COCO: 101-point AP per class, IoU thresholds .5:.95, best same-class GT;
DAROD: all-point AP, class-agnostic best-GT matching, score > 0.5, 30 boxes): a figure is compared
only with one of the same protocol (metrics/boxes2d). Classes without ground truth in the scored
samples have no AP and stay out of the per-class tables and the means, as pycocotools does.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

from ...boxes.boxes2d import Boxes2D
from ...data.rd.sample import RDSample
from ...metrics.boxes2d.coco import coco_evaluate
from ...metrics.boxes2d.darod import darod_evaluate
from ..base import ALL_CLASSES, Protocol


def _percent(value: float) -> float | None:
    return None if value is None or math.isnan(value) else round(100.0 * float(value), 4)


def score_rd(gts: Mapping[str, Boxes2D], dets: Mapping[str, Boxes2D], classes: Sequence[str],
             match_classes: Sequence[str] = ()) -> dict:
    """COCO and DAROD figures of detections against ground truth (sample id -> Boxes2D, every
    scored sample, empty ones included); ValueError for no samples. `match_classes` adds
    "match_tables": {class: MatchTable (kind "coco")} for bootstrap intervals over the samples."""
    if not gts:
        raise ValueError("no samples to score: the ground truth mapping is empty (an empty split?)")
    coco = coco_evaluate(gts, {k: dets[k] for k in gts}, tuple(classes), match_classes=tuple(match_classes))
    darod = darod_evaluate(gts, {k: dets[k] for k in gts}, tuple(classes))
    per_class = {n: _percent(v) for n, v in coco.per_class_ap.items()}
    per_class50 = {n: _percent(v) for n, v in coco.per_class_ap50.items()}
    return {"mAP50": _percent(coco.ap50), "mAP50_95": _percent(coco.map), "mAP30": _percent(coco.ap30),
            "mAP70": _percent(coco.ap70), "mAP75": _percent(coco.ap75),
            "AP": {n: v for n, v in per_class.items() if v is not None},
            "AP50": {n: v for n, v in per_class50.items() if v is not None},
            **{f"darod_mAP{round(100 * t)}": _percent(darod.map_at(t)) for t in darod.iou_thresholds},
            "num_gt": {n: int(k) for n, k in zip(darod.classes, darod.n_gt)}, "samples": len(gts),
            **({"match_tables": coco.match_tables} if match_classes else {})}


def ground_truth(samples: Sequence[RDSample]) -> dict[str, Boxes2D]:
    return {s.sample_id: s.boxes for s in (samples[i] for i in range(len(samples)))}


def evaluate_rd(predictor, samples: Sequence[RDSample], match_classes: Sequence[str] = ()
                ) -> tuple[dict, dict[str, Boxes2D]]:
    """Predict `samples` and score them -> (scores, detections); see score_rd for `match_classes`."""
    detections = predictor.predict_samples(samples)
    return score_rd(ground_truth(samples), detections, predictor.classes, match_classes), detections


def summary(scores: dict) -> str:
    def fmt(v):
        return "n/a" if v is None else f"{v:.2f}"
    return (f"mAP@50 {fmt(scores['mAP50'])}  mAP@50-95 {fmt(scores['mAP50_95'])}  mAP@30 {fmt(scores['mAP30'])}  "
            f"DAROD mAP@50 {fmt(scores['darod_mAP50'])}")


# --- the rd_coco protocol (the record's `protocols`: modalities/rd/record.py)

def validate(predictor, samples: Sequence[RDSample], match_classes: Sequence[str] = ()) -> tuple[dict, dict]:
    """Scores (mAP@50 headline) and the COCO match tables of `match_classes` (ALL_CLASSES: every class)."""
    scores = evaluate_rd(predictor, samples, [c for c in predictor.classes if c in match_classes or
                                              ALL_CLASSES in match_classes])[0]
    return scores, scores.pop("match_tables", {})


def report(samples: Sequence[RDSample], detections: Mapping[str, Boxes2D], predictor) -> tuple[dict, str]:
    result = {"protocol": "rd_coco", **score_rd(ground_truth(samples), detections, predictor.classes)}
    return result, summary(result)


PROTOCOLS = {"rd_coco": Protocol(validate, report)}  # the record's `protocols`

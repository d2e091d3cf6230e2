"""Score detections on camera images: VOC mAP@0.5 as py-faster-rcnn's voc_eval.py computes it (VOC07
11-point, the headline, and all-point; strict IoU > 0.5 with +1-pixel widths, difficult objects
neither TP nor FP: metrics/boxes2d/voc_ap.py) and COCO mAP@[.5:.95] and AP50 through pycocotools
(metrics/boxes2d/coco.py; difficult boxes go in as iscrowd, COCO's nearest notion, as voc_coco
writes them), per class, in percent, on the images' pixel boxes.

The classes scored are the predictor's (`predictor.classes`: the model's, or a data source's names
through a class map, modalities/image/predict.py). Ground truth of other classes is left out, since the model
cannot name it (a street-trained model on VOC scores car, bus, person and bicycle only), and the
result counts what was left out per class. A class without non-difficult ground truth in the scored
images has no AP and stays out of the means (voc_ap, pycocotools).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from ...boxes.boxes2d import Boxes2D
from ...data.camera.images import CameraImage
from ...metrics.boxes2d.coco import coco_evaluate
from ...metrics.boxes2d.voc_ap import voc_ap
from ..base import Protocol


def percent(value) -> float | None:
    return None if value is None or math.isnan(value) else round(100.0 * float(value), 4)


def ground_truth(images: Sequence[CameraImage], classes: Sequence[str]) -> tuple[dict[str, Boxes2D], dict[str, int]]:
    """(image id -> its boxes of `classes` (difficult flags kept), class -> boxes left out)."""
    gts, left_out = {}, {}
    for item in (images[i] for i in range(len(images))):
        keep = np.isin(item.boxes.names, list(classes))
        for name in item.boxes.names[~keep]:
            left_out[str(name)] = left_out.get(str(name), 0) + 1
        gts[item.image_id] = item.boxes.select(keep)
    return gts, dict(sorted(left_out.items()))


def score_camera(gts: Mapping[str, Boxes2D], dets: Mapping[str, Boxes2D], classes: Sequence[str]) -> dict:
    """VOC and COCO figures of detections against ground truth (image id -> Boxes2D, every scored
    image, empty ones included); ValueError for no images."""
    if not gts:
        raise ValueError("no images to score: the ground truth mapping is empty (an empty split?)")
    dets = {k: dets[k] for k in gts}
    classes = tuple(classes)
    voc07 = voc_ap(gts, dets, classes, iou_threshold=0.5, metric="voc07")
    voc_all = voc_ap(gts, dets, classes, iou_threshold=0.5, metric="all")
    crowd = {k: (np.zeros(len(b), bool) if b.difficult is None else np.asarray(b.difficult, bool))
             for k, b in gts.items()}
    coco = coco_evaluate(gts, dets, classes, iscrowd=crowd)
    scored = [c for k, c in enumerate(classes) if voc07.npos[k] > 0]

    def per_class(values):
        return {c: percent(values[c]) for c in scored}

    return {"mAP50": percent(voc07.map), "mAP50_all": percent(voc_all.map), "coco_mAP50_95": percent(coco.map),
            "coco_AP50": percent(coco.ap50), "coco_AP75": percent(coco.ap75),
            "AP50": per_class(dict(zip(classes, voc07.ap))), "AP50_all": per_class(dict(zip(classes, voc_all.ap))),
            "coco_AP": per_class(coco.per_class_ap), "num_gt": {c: int(n) for c, n in zip(classes, voc07.npos)},
            "num_det": {c: int(n) for c, n in zip(classes, voc07.n_det)}, "images": len(gts)}


def evaluate_camera(predictor, images: Sequence[CameraImage]) -> tuple[dict, dict[str, Boxes2D]]:
    """Predict `images` and score them with the predictor's classes -> (scores, detections)."""
    detections = predictor.predict_samples(images)
    return score_images(images, detections, predictor.classes), detections


def score_images(images: Sequence[CameraImage], detections: Mapping[str, Boxes2D], classes: Sequence[str]) -> dict:
    """`score_camera` on the images' ground truth of `classes`, with the counts of what was left out."""
    gts, left_out = ground_truth(images, classes)
    return {**score_camera(gts, detections, classes), "classes": list(classes), "gt_left_out": left_out}


def summary(scores: dict) -> str:
    def fmt(v):
        return "n/a" if v is None else f"{v:.2f}"
    per_class = "  ".join(f"{c} {fmt(v)}" for c, v in scores["AP50"].items())
    return (f"VOC07 mAP@0.5 {fmt(scores['mAP50'])}  all-point {fmt(scores['mAP50_all'])}  "
            f"COCO mAP@[.5:.95] {fmt(scores['coco_mAP50_95'])}  AP50 {fmt(scores['coco_AP50'])}  ({per_class})")


# --- the camera_voc protocol (the record's `protocols`: modalities/image/record.py)

def validate(predictor, images: Sequence[CameraImage], match_classes: Sequence[str] = ()) -> tuple[dict, dict]:
    """Scores (VOC07 mAP@0.5 headline); no per-image match tables (no bootstrap intervals yet)."""
    return evaluate_camera(predictor, images)[0], {}


def report(images: Sequence[CameraImage], detections: Mapping[str, Boxes2D], predictor) -> tuple[dict, str]:
    result = {"protocol": "camera_voc", **score_images(images, detections, predictor.classes)}
    return result, summary(result)


PROTOCOLS = {"camera_voc": Protocol(validate, report)}  # the record's `protocols`

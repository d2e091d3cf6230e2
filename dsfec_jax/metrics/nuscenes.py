"""The nuScenes detection AP, computed the way nuscenes-devkit 1.2.0 (config ``detection_cvpr_2019``) does.

What the devkit does, and so what this module does (numpy only, no devkit import):

* Matching is by centre distance in the ground plane (x, y only), never IoU, so a radar detector with poor
  box extents is still credited for finding the object.
* Per class and distance threshold, all predictions of that class from all samples are taken highest score
  first; each is matched to the nearest still-unmatched ground-truth box of the same class in the same sample,
  and is a true positive only if that distance is strictly below the threshold.
* Precision and recall (tp / npos) are resampled on 101 recall points with ``np.interp(..., right=0)``; AP
  drops the bins up to and including ``min_recall`` = 0.1, subtracts ``min_precision`` = 0.1, clips at 0 and
  divides by 0.9. A class's mAP is the mean over the thresholds 0.5, 1, 2, 4 m; the overall mAP is the mean
  over classes. The DSFEC paper (§4.2) reports Car "AP@4" and Car "mAP" this way, in percent.
* TP errors (translation, scale, orientation, velocity, attribute) are cumulative means over the matches,
  resampled on the same recall points, averaged from just above min_recall up to the maximum recall reached,
  at ``dist_th_tp`` = 2 m.
* Before matching, boxes farther from the ego than the class range (50 m vehicles, 40 m pedestrians and
  two-wheelers, 30 m cones and barriers) and boxes with ``num_pts == 0`` (no lidar + radar point inside) are
  dropped, from ground truth and predictions alike (predictions carry ``num_pts = -1`` so survive); the devkit
  also drops bicycles/motorcycles inside bicycle racks, which needs the nuScenes database and is not done here.
* A submission holds at most 500 boxes per sample, and must cover exactly the ground truth's samples.

Boxes are plain dicts in the official submission format (``translation``, ``size`` (w, l, h), ``rotation``
quaternion (w, x, y, z), ``velocity`` (vx, vy), ``detection_name``, ``detection_score``, ``attribute_name``;
ground truth may add ``num_pts`` and have no score), grouped as ``{sample_token: [box, ...]}``. The project's
frames are in the ego/sensor frame, so a box's ego distance is its own (x, y) norm unless it carries an
``ego_translation`` (give one when the frame is not the ego frame).
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import json
import math
import sys
from typing import Mapping, Sequence

import numpy as np

from .submission import MAX_BOXES_PER_SAMPLE, _as_results, quaternion_to_yaw, read_submission

CLASS_RANGE = {"car": 50.0, "truck": 50.0, "bus": 50.0, "trailer": 50.0, "construction_vehicle": 50.0,
               "pedestrian": 40.0, "motorcycle": 40.0, "bicycle": 40.0, "traffic_cone": 30.0, "barrier": 30.0}
DIST_THS = (0.5, 1.0, 2.0, 4.0)
DIST_TH_TP = 2.0
MIN_RECALL = 0.1
MIN_PRECISION = 0.1
TP_METRICS = ("trans_err", "scale_err", "orient_err", "vel_err", "attr_err")
DSFEC_CLASSES = ("car", "truck", "pedestrian", "bicycle")
NELEM = 101  # recall points 0, 0.01, ..., 1


# ----------------------------------------------------------------------------------------------------------
# Curves and the two summary functions
# ----------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class MetricData:
    """One class at one threshold, resampled on 101 recall points (the devkit's DetectionMetricData)."""

    recall: np.ndarray
    precision: np.ndarray
    confidence: np.ndarray
    trans_err: np.ndarray
    vel_err: np.ndarray
    scale_err: np.ndarray
    orient_err: np.ndarray
    attr_err: np.ndarray

    @classmethod
    def no_predictions(cls) -> "MetricData":
        """No GT of the class, or no prediction matched: precision 0 everywhere (AP 0), errors 1."""
        ones = np.ones(NELEM)
        return cls(np.linspace(0, 1, NELEM), np.zeros(NELEM), np.zeros(NELEM), ones, ones, ones, ones, ones)

    @property
    def max_recall_ind(self) -> int:
        """Last recall bin with non-zero confidence: interpolation gives 0 beyond the highest recall reached."""
        nonzero = np.nonzero(self.confidence)[0]
        return int(nonzero[-1]) if len(nonzero) else 0

    @property
    def max_recall(self) -> float:
        return float(self.recall[self.max_recall_ind])


def calc_ap(md: MetricData, min_recall: float = MIN_RECALL, min_precision: float = MIN_PRECISION) -> float:
    """AP as the devkit defines it: the low-recall bins (up to and including min_recall) are noisy, so they are
    dropped; precision below min_precision counts as 0, and the result is rescaled so a perfect curve gives 1."""
    if not (0 <= min_precision < 1 and 0 <= min_recall <= 1):
        raise ValueError(f"need 0 <= min_precision < 1 and 0 <= min_recall <= 1; got {min_precision}, {min_recall}")
    return ap_of_precision(md.precision, min_recall, min_precision)


def ap_of_precision(precision: np.ndarray, min_recall: float = MIN_RECALL, min_precision: float = MIN_PRECISION) -> float:
    """`calc_ap` of a precision curve on the 101 recall points."""
    prec = np.copy(precision)[round(100 * min_recall) + 1:] - min_precision
    prec[prec < 0] = 0
    return float(np.mean(prec)) / (1.0 - min_precision)


def calc_tp(md: MetricData, min_recall: float = MIN_RECALL, metric_name: str = "trans_err") -> float:
    """Mean of a TP error over the recall bins above min_recall up to the highest recall reached (inclusive);
    1.0 (the worst normalised error) when the class never gets past min_recall."""
    first, last = round(100 * min_recall) + 1, md.max_recall_ind
    if last < first:
        return 1.0
    return float(np.mean(getattr(md, metric_name)[first:last + 1]))


# ----------------------------------------------------------------------------------------------------------
# Per-match errors (devkit common/utils.py semantics)
# ----------------------------------------------------------------------------------------------------------

def angle_diff(x: float, y: float, period: float) -> float:
    """Signed smallest difference x - y modulo ``period`` (pi for barriers, whose front is undefined)."""
    diff = (np.float64(x) - y + period / 2) % period - period / 2
    if diff > np.pi:
        diff = diff - 2 * np.pi
    return float(diff)


def _center_distance(a: Mapping, b: Mapping) -> float:
    dx, dy = b["translation"][0] - a["translation"][0], b["translation"][1] - a["translation"][1]
    return float(np.sqrt(dx * dx + dy * dy))


def _scale_iou(gt: Mapping, pred: Mapping) -> float:
    """3D IoU of the two boxes after aligning centres and headings, so only the sizes count."""
    sg, sp = np.asarray(gt["size"], float), np.asarray(pred["size"], float)
    inter = np.prod(np.minimum(sg, sp))
    return float(inter / (np.prod(sg) + np.prod(sp) - inter))


def _match_errors(gt: Mapping, pred: Mapping, class_name: str) -> dict[str, float]:
    period = np.pi if class_name == "barrier" else 2 * np.pi
    yaw_gt, yaw_pred = quaternion_to_yaw(gt["rotation"]), quaternion_to_yaw(pred["rotation"])
    attr_acc = np.nan if gt["attribute_name"] == "" else float(gt["attribute_name"] == pred["attribute_name"])
    return {"trans_err": _center_distance(gt, pred),
            "vel_err": float(np.linalg.norm(np.asarray(pred["velocity"], float) - np.asarray(gt["velocity"], float))),
            "scale_err": 1.0 - _scale_iou(gt, pred),
            "orient_err": abs(angle_diff(yaw_gt, yaw_pred, period)),
            "attr_err": 1.0 - attr_acc}


def _cummean(x: np.ndarray) -> np.ndarray:
    """Running mean ignoring NaNs (missing attributes / velocities); all-NaN gives 1, the worst error."""
    if np.all(np.isnan(x)):
        return np.ones(len(x))
    sums, counts = np.nancumsum(x.astype(float)), np.cumsum(~np.isnan(x))
    return np.divide(sums, counts, out=np.zeros_like(sums), where=counts != 0)


# ----------------------------------------------------------------------------------------------------------
# Matching
# ----------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ClassCandidates:
    """One class's predictions in the devkit's order, each with the GT boxes it could match, nearest first.

    Distances and per-pair errors do not depend on the threshold, so they are computed once for all of them."""

    npos: int
    preds: list           # [(sample_token, box)] highest score first
    candidates: list      # per prediction: ([gt index], [distance]) ascending distance, ties by GT index
    gts: dict             # sample_token -> [GT boxes of this class]
    errors: dict = dataclasses.field(default_factory=dict)  # (pred rank, GT index) -> TP errors


def _sample_candidates(boxes: list, gts: list, max_dist: float) -> list:
    """For each prediction of one sample: GT indices nearer than max_dist, nearest first, with distances."""
    p_Px2 = np.array([b["translation"][:2] for b in boxes], float).reshape(-1, 2)
    g_Gx2 = np.array([b["translation"][:2] for b in gts], float).reshape(-1, 2)
    diff = p_Px2[:, None, :] - g_Gx2[None, :, :]
    d_PxG = np.sqrt(diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1])
    idx = np.argsort(d_PxG, axis=1, kind="stable")  # stable: the lowest GT index wins a tie, as the devkit's '<'
    dist = np.take_along_axis(d_PxG, idx, axis=1)
    out = []
    for row_i, row_d in zip(idx.tolist(), dist.tolist()):
        n = bisect.bisect_left(row_d, max_dist)  # how many are strictly nearer than max_dist
        out.append((row_i[:n], row_d[:n]))
    return out


def class_candidates(gt: Mapping, pred: Mapping, class_name: str, max_dist: float) -> ClassCandidates:
    gts = {tok: [b for b in boxes if b["detection_name"] == class_name] for tok, boxes in gt.items()}
    preds, candidates = [], []
    for tok, boxes in pred.items():  # the devkit's order: samples as listed, boxes as listed
        mine = [b for b in boxes if b["detection_name"] == class_name]
        preds += [(tok, b) for b in mine]
        candidates += _sample_candidates(mine, gts.get(tok, []), max_dist) if mine else []
    # The devkit sorts (score, index) pairs and reverses: highest score first, ties to the later prediction.
    order = sorted(range(len(preds)), key=lambda i: (preds[i][1]["detection_score"], i), reverse=True)
    return ClassCandidates(sum(len(b) for b in gts.values()), [preds[i] for i in order],
                            [candidates[i] for i in order], gts)


def _match(cc: ClassCandidates, class_name: str, dist_th: float) -> MetricData:
    if cc.npos == 0:
        return MetricData.no_predictions()
    is_tp, matches = greedy_match(cc, class_name, dist_th)
    if not matches:
        return MetricData.no_predictions()
    return _curves(is_tp, np.array([b["detection_score"] for _, b in cc.preds], float), matches, cc.npos)


def greedy_match(cc: ClassCandidates, class_name: str, dist_th: float) -> tuple[np.ndarray, list]:
    """Greedy matching, highest score first: nearest still-unmatched GT, a hit only if strictly below dist_th.
    -> (1.0 / 0.0 per prediction in cc.preds' order, [(score, TP errors)] of the hits)."""
    taken = {tok: np.zeros(len(b), bool) for tok, b in cc.gts.items()}
    is_tp, matches = np.zeros(len(cc.preds)), []
    for k, ((tok, box), (idx, dist)) in enumerate(zip(cc.preds, cc.candidates)):
        for j, d in zip(idx, dist):
            if d >= dist_th:
                break  # the nearest untaken GT is too far: a false positive
            if not taken[tok][j]:
                taken[tok][j], is_tp[k] = True, 1.0
                if (k, j) not in cc.errors:
                    cc.errors[k, j] = _match_errors(cc.gts[tok][j], box, class_name)
                matches.append((box["detection_score"], cc.errors[k, j]))
                break
    return is_tp, matches


def _curves(is_tp: np.ndarray, conf: np.ndarray, matches: list, npos: int) -> MetricData:
    """Cumulative precision/recall resampled on 101 recall points; per-match errors resampled by confidence."""
    tp, fp = np.cumsum(is_tp), np.cumsum(1.0 - is_tp)
    rec_interp = np.linspace(0, 1, NELEM)
    precision = np.interp(rec_interp, tp / float(npos), tp / (fp + tp), right=0)
    confidence = np.interp(rec_interp, tp / float(npos), conf, right=0)
    match_conf = np.array([score for score, _ in matches], float)
    resampled = {}
    for key in TP_METRICS:
        mean = _cummean(np.array([errors[key] for _, errors in matches], float))
        # np.interp needs increasing x, hence the reversals (confidences fall as recall rises).
        resampled[key] = np.interp(confidence[::-1], match_conf[::-1], mean[::-1])[::-1]
    return MetricData(rec_interp, precision, confidence, **resampled)


def accumulate(gt: Mapping[str, list], pred: Mapping[str, list], class_name: str, dist_th: float) -> MetricData:
    """The devkit's ``accumulate`` for one class and one centre-distance threshold (metres).

    ``gt`` and ``pred`` map sample tokens to lists of box dicts (already filtered; see ``filter_boxes``)."""
    return _match(class_candidates(gt, pred, class_name, dist_th), class_name, dist_th)


# ----------------------------------------------------------------------------------------------------------
# Filters and the whole evaluation
# ----------------------------------------------------------------------------------------------------------

def ego_distance(box: Mapping) -> float:
    """Ground-plane distance from the ego: ``ego_translation`` when given, else the box's own translation."""
    x, y = (box.get("ego_translation") or box["translation"])[:2]
    return math.sqrt(x * x + y * y)


def filter_boxes(boxes: Mapping[str, list], class_range: Mapping[str, float] | None = CLASS_RANGE,
                 drop_empty: bool = True) -> dict[str, list]:
    """The devkit's ``filter_eval_boxes`` without the bike-rack step (which needs the nuScenes database).

    Keeps boxes strictly nearer than their class range (classes not in ``class_range`` are kept; ``None``
    turns the range filter off) and, with ``drop_empty``, drops boxes whose ``num_pts`` is 0: a GT box no
    lidar or radar point hit cannot be detected. Predictions carry ``num_pts = -1`` and so are never dropped
    by it. Sources without lidar leave ``num_pts`` at -1 rather than count radar points alone (see
    ``dsfec_jax.modalities.points.evaluate.score``: a radar-only count would drop exactly the objects the radar missed)."""
    out = {}
    for tok, lst in boxes.items():
        keep = [b for b in lst if class_range is None or b["detection_name"] not in class_range
                or ego_distance(b) < class_range[b["detection_name"]]]
        out[tok] = [b for b in keep if not (drop_empty and b.get("num_pts", -1) == 0)]
    return out


def _check_samples(gt: Mapping, pred: Mapping, max_boxes_per_sample: int | None, same_samples: bool) -> None:
    if max_boxes_per_sample is not None:
        for tok, boxes in pred.items():
            if len(boxes) > max_boxes_per_sample:
                raise ValueError(f"sample {tok!r} has {len(boxes)} predicted boxes; at most "
                                 f"{max_boxes_per_sample} are allowed")
    if same_samples and set(gt) != set(pred):
        missing, extra = sorted(set(gt) - set(pred)), sorted(set(pred) - set(gt))
        raise ValueError(f"predictions must cover exactly the GT samples (as the devkit requires): "
                         f"{len(missing)} missing (e.g. {missing[:3]}), {len(extra)} extra (e.g. {extra[:3]})")


def prepare(gt: Mapping, pred: Mapping, class_range: Mapping[str, float] | None = CLASS_RANGE,
            drop_empty_gt: bool = True, max_boxes_per_sample: int | None = MAX_BOXES_PER_SAMPLE,
            same_samples: bool = True) -> tuple[dict, dict]:
    """Both sides in the submission format, checked and filtered as `evaluate` does before matching.
    ValueError when the ground truth holds no sample."""
    if not gt:  # else every AP is a silent 0: an empty split or a wrong --subset, not a bad detector
        raise ValueError("no samples to score: the ground truth holds no sample (is the evaluation set empty?)")
    gt = filter_boxes(_as_results(gt, True), class_range, drop_empty_gt)
    pred = _as_results(pred, False)
    _check_samples(gt, pred, max_boxes_per_sample, same_samples)
    return gt, filter_boxes(pred, class_range, drop_empty_gt)


def _tp_errors(md: MetricData, class_name: str, min_recall: float) -> dict[str, float]:
    """TP errors at dist_th_tp; the devkit reports NaN where a class has no such property."""
    out = {}
    for name in TP_METRICS:
        undefined = (class_name == "traffic_cone" and name in ("attr_err", "vel_err", "orient_err")) or \
                    (class_name == "barrier" and name in ("attr_err", "vel_err"))
        out[name] = float("nan") if undefined else calc_tp(md, min_recall, name)
    return out


def evaluate(gt: Mapping, pred: Mapping, classes: Sequence[str] = DSFEC_CLASSES,
             dist_ths: Sequence[float] = DIST_THS, *, dist_th_tp: float = DIST_TH_TP,
             min_recall: float = MIN_RECALL, min_precision: float = MIN_PRECISION,
             class_range: Mapping[str, float] | None = CLASS_RANGE, drop_empty_gt: bool = True,
             max_boxes_per_sample: int | None = MAX_BOXES_PER_SAMPLE, same_samples: bool = True) -> dict:
    """Per-class AP at each threshold, per-class mAP over thresholds (the DSFEC "mAP"), AP@4 and overall mAP.

    ``gt`` / ``pred`` map sample tokens to lists of submission-format box dicts, or to ``Boxes`` (GT) /
    ``(Boxes, scores)`` (predictions). Defaults follow the devkit: class ranges, the num_pts == 0 filter, at
    most 500 predictions per sample and identical sample sets. Values are fractions (the paper prints %).
    Zero samples raise ValueError: there is nothing to average, and every AP would be a silent 0.

    Returns ``{"AP": {cls: {"0.5": ap, ...}}, "class_mAP": {cls: mean over thresholds}, "AP@4": {cls: ap},
    "mAP": mean of class_mAP, "max_recall": {cls: {th: r}}, "tp_errors": {cls: {err: value at dist_th_tp}},
    "num_gt"/"num_pred": {cls: count after filtering}, "classes", "dist_ths"}``; thresholds keyed as str(float)."""
    gt, pred = prepare(gt, pred, class_range, drop_empty_gt, max_boxes_per_sample, same_samples)
    keys = [str(float(th)) for th in dist_ths]
    out = {"classes": list(classes), "dist_ths": [float(t) for t in dist_ths], "AP": {}, "max_recall": {},
           "class_mAP": {}, "tp_errors": {}, "num_gt": {}, "num_pred": {}}
    for name in classes:
        cc = class_candidates(gt, pred, name, max(*dist_ths, dist_th_tp))
        mds = {key: _match(cc, name, float(th)) for key, th in zip(keys, dist_ths)}
        out["AP"][name] = {key: calc_ap(md, min_recall, min_precision) for key, md in mds.items()}
        out["max_recall"][name] = {key: md.max_recall for key, md in mds.items()}
        out["class_mAP"][name] = float(np.mean(list(out["AP"][name].values())))
        out["tp_errors"][name] = _tp_errors(_match(cc, name, dist_th_tp), name, min_recall)
        out["num_gt"][name], out["num_pred"][name] = cc.npos, len(cc.preds)
    if "4.0" in keys:
        out["AP@4"] = {name: out["AP"][name]["4.0"] for name in classes}
    out["mAP"] = float(np.mean(list(out["class_mAP"].values()))) if classes else float("nan")
    return out


# ----------------------------------------------------------------------------------------------------------
# CLI
# ----------------------------------------------------------------------------------------------------------

def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_jsonable(v) for v in x]
    return None if isinstance(x, float) and math.isnan(x) else x


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m dsfec_jax.metrics.nuscenes --gt GT.json --pred PRED.json``: prints the metrics as JSON."""
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.metrics.nuscenes", description=__doc__.split("\n")[0])
    p.add_argument("--gt", required=True, help="ground truth in the submission format")
    p.add_argument("--pred", required=True, help="submission JSON")
    p.add_argument("--classes", default=",".join(DSFEC_CLASSES), help="comma-separated class names")
    p.add_argument("--dist-ths", default="0.5,1,2,4", help="comma-separated centre-distance thresholds (m)")
    p.add_argument("--no-range-filter", action="store_true", help="keep boxes beyond the class ranges")
    p.add_argument("--keep-empty-gt", action="store_true", help="keep GT boxes with num_pts == 0")
    p.add_argument("--subset", action="store_true", help="allow predictions for a subset of the GT samples")
    args = p.parse_args(argv)
    try:  # bad files and empty inputs end the command with their message, not a traceback
        gt, _ = read_submission(args.gt, is_gt=True)
        pred, _ = read_submission(args.pred)
        if args.subset:
            gt = {t: gt.get(t, []) for t in pred}
        result = evaluate(gt, pred, classes=[c for c in args.classes.split(",") if c],
                          dist_ths=[float(t) for t in args.dist_ths.split(",")],
                          class_range=None if args.no_range_filter else CLASS_RANGE,
                          drop_empty_gt=not args.keep_empty_gt)
    except (ValueError, FileNotFoundError) as err:
        sys.exit(f"{p.prog}: {err}")
    json.dump(_jsonable(result), sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""VoD / KITTI 3D AP: hand-computed cases and a loop-by-loop reference with shapely IoU."""

import math

import numpy as np
import pytest

from dsfec_jax.metrics import kitti3d

try:
    from shapely.geometry import Polygon
except ImportError:  # pragma: no cover - shapely is a dev dependency
    Polygon = None


def car(x, y, yaw=0.0, z=0.0, cls="Car", size=(1.8, 4.2, 1.5)):
    return cls, [x, y, z, *size, yaw]


def frame(*boxes, scores=None):
    out = {"names": [b[0] for b in boxes], "boxes": np.array([b[1] for b in boxes]).reshape(-1, 7)}
    if scores is not None:
        out["scores"] = np.array(scores, float)
    return out


def test_perfect_detections_follow_kittis_41_point_sampling():
    # 80 ground truths: the 41 sampled thresholds cover recall 0..1 -> 100
    gts = [frame(*[car(5.0 * i, 0.0) for i in range(8)]) for _ in range(10)]
    dets = [dict(g, scores=np.linspace(0.9, 0.5, 8)) for g in gts]
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5})["AP"]["Car"] == pytest.approx(100.0)
    # 40 ground truths fill only 40 of the 41 points: the last 11-point sample reads 0 (KITTI R11)
    gts, dets = gts[:5], dets[:5]
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5})["AP"]["Car"] == pytest.approx(1000 / 11)


def test_a_higher_scored_false_positive_halves_the_only_precision_point():
    gts = [frame(car(10, 0))]
    dets = [frame(car(30, 5), car(10.1, 0), scores=[0.9, 0.8])]
    # one TP score -> one threshold (0.8): precision 1/2 at sample 0 only -> 0.5 / 11
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5})["AP"]["Car"] == pytest.approx(100 / 22)


def test_iou_threshold_and_class_matter():
    gts = [frame(car(10, 0), car(20, 0, cls="Pedestrian", size=(0.6, 0.8, 1.7)))]
    shifted = frame(car(10.0, 0.9), car(20.2, 0, cls="Pedestrian", size=(0.6, 0.8, 1.7)), scores=[0.9, 0.9])
    res = kitti3d.evaluate(gts, [shifted])
    assert res["AP"]["Car"] == 0.0  # lateral 0.9 m on a 1.8 m wide car: IoU 1/3 < 0.5
    assert res["AP"]["Pedestrian"] > 0  # IoU 0.6 > 0.25
    assert math.isnan(res["AP"]["Cyclist"]) and res["num_gt"]["Cyclist"] == 0
    assert res["mAP"] == pytest.approx(np.mean([res["AP"]["Car"], res["AP"]["Pedestrian"]]))


def test_neighbouring_van_absorbs_a_car_detection():
    gts = [frame(car(10, 0), car(25, 0, cls="Van"))]
    dets = [frame(car(25, 0), car(10, 0), scores=[0.9, 0.8])]
    # without the neighbour rule the Van-matched detection would be a false positive (AP 100/22)
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5})["AP"]["Car"] == pytest.approx(100 / 11)


def test_the_corridor_ignores_boxes_outside_it():
    gts = [frame(car(10, 0), car(10, 8))]
    dets = [frame(car(10, 8), car(30, 0), car(10, 0), scores=[0.9, 0.85, 0.8])]
    entire = kitti3d.evaluate(gts, dets, {"Car": 0.5}, "entire")
    corridor = kitti3d.evaluate(gts, dets, {"Car": 0.5}, "corridor")
    assert entire["num_gt"]["Car"] == 2 and corridor["num_gt"]["Car"] == 1
    # corridor: the y = 8 and x = 30 boxes are ignored, leaving one perfect match
    assert corridor["AP"]["Car"] == pytest.approx(100 / 11)
    assert set(kitti3d.evaluate_vod(gts, dets, {"Car": 0.5})) == {"entire", "corridor"}


def test_bad_frames_are_named():
    with pytest.raises(ValueError, match="detections frame 0.*scores"):
        kitti3d.evaluate([frame(car(1, 1))], [frame(car(1, 1))])
    with pytest.raises(ValueError, match="ground truth frame 0: 2 names but 1 boxes"):
        kitti3d.evaluate([{"names": ["Car", "Car"], "boxes": np.zeros((1, 7))}], [frame(scores=[])])
    with pytest.raises(ValueError, match="region"):
        kitti3d.evaluate([], [], region="city")


# ---------------------------------------------------------------------------------------------
# Reference: the official evaluation's loops transcribed one statement at a time, with shapely IoU.

def shapely_iou_3d(a, b):
    def poly(box):
        x, y, _, w, l, _, yaw = box
        c, s = math.cos(yaw), math.sin(yaw)
        pts = [(dl * l / 2, dw * w / 2) for dl, dw in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
        return Polygon([(x + px * c - py * s, y + px * s + py * c) for px, py in pts])
    inter_h = max(0.0, min(a[2] + a[5] / 2, b[2] + b[5] / 2) - max(a[2] - a[5] / 2, b[2] - b[5] / 2))
    inter = poly(a).intersection(poly(b)).area * inter_h
    return inter / (a[3] * a[4] * a[5] + b[3] * b[4] * b[5] - inter)


def reference_statistics(overlaps, ignored_gt, ignored_det, scores, min_overlap, thresh, compute_fp):
    det_size, gt_size = len(scores), len(ignored_gt)
    assigned = [False] * det_size
    ignored_threshold = [compute_fp and scores[j] < thresh for j in range(det_size)]
    tp = fp = fn = 0
    thresholds = []
    for i in range(gt_size):
        if ignored_gt[i] == -1:
            continue
        det_idx, valid_detection, max_overlap, assigned_ignored_det = -1, -1e7, 0.0, False
        for j in range(det_size):
            if ignored_det[j] == -1 or assigned[j] or ignored_threshold[j]:
                continue
            overlap = overlaps[j][i]
            if not compute_fp and overlap > min_overlap and scores[j] > valid_detection:
                det_idx, valid_detection = j, scores[j]
            elif (compute_fp and overlap > min_overlap and (overlap > max_overlap or assigned_ignored_det)
                  and ignored_det[j] == 0):
                max_overlap, det_idx, valid_detection, assigned_ignored_det = overlap, j, 1, False
            elif compute_fp and overlap > min_overlap and valid_detection == -1e7 and ignored_det[j] == 1:
                det_idx, valid_detection, assigned_ignored_det = j, 1, True
        if valid_detection == -1e7 and ignored_gt[i] == 0:
            fn += 1
        elif valid_detection != -1e7 and (ignored_gt[i] == 1 or ignored_det[det_idx] == 1):
            assigned[det_idx] = True
        elif valid_detection != -1e7:
            tp += 1
            thresholds.append(scores[det_idx])
            assigned[det_idx] = True
    if compute_fp:
        for j in range(det_size):
            if not (assigned[j] or ignored_det[j] == -1 or ignored_det[j] == 1 or ignored_threshold[j]):
                fp += 1
    return tp, fp, fn, thresholds


def reference_thresholds(scores, num_gt, num_sample_pts=41):
    scores = sorted(scores, reverse=True)
    current_recall, thresholds = 0.0, []
    for i, score in enumerate(scores):
        l_recall = (i + 1) / num_gt
        r_recall = (i + 2) / num_gt if i < len(scores) - 1 else l_recall
        if (r_recall - current_recall) < (current_recall - l_recall) and i < len(scores) - 1:
            continue
        thresholds.append(score)
        current_recall += 1 / (num_sample_pts - 1.0)
    return thresholds


def reference_ap(gts, dets, cls, min_overlap, region):
    prepared, num_gt, all_scores = [], 0, []
    for gt, det in zip(gts, dets):
        def out(box):
            return region == "corridor" and (abs(box[1]) > 4.0 or box[0] > 25.0)
        ig = []
        for name, box in zip(gt["names"], gt["boxes"]):
            name = name.lower()
            if name == cls.lower() and not out(box):
                ig.append(0)
            elif name in {"car": ["van"], "pedestrian": ["person_sitting"]}.get(cls.lower(), []) or name == cls.lower():
                ig.append(1)
            else:
                ig.append(-1)
        idt = [(1 if out(box) else 0) if name.lower() == cls.lower() else -1
               for name, box in zip(det["names"], det["boxes"])]
        ov = [[shapely_iou_3d(d, g) for g in gt["boxes"]] for d in det["boxes"]]
        prepared.append((ov, ig, idt, list(det["scores"])))
        num_gt += ig.count(0)
        all_scores += reference_statistics(ov, ig, idt, list(det["scores"]), min_overlap, 0.0, False)[3]
    thresholds = reference_thresholds(all_scores, num_gt)
    precision = [0.0] * 41
    for t, thr in enumerate(thresholds):
        tp = fp = 0
        for ov, ig, idt, sc in prepared:
            a, b, _, _ = reference_statistics(ov, ig, idt, sc, min_overlap, thr, True)
            tp, fp = tp + a, fp + b
        precision[t] = tp / (tp + fp)
    for i in range(len(thresholds)):
        precision[i] = max(precision[i:])
    return sum(precision[i] for i in range(0, 41, 4)) / 11 * 100


def random_scene(rng, n_frames=6):
    gts, dets = [], []
    sizes = {"Car": (1.8, 4.2, 1.5), "Van": (2.0, 5.0, 2.0), "Pedestrian": (0.6, 0.8, 1.7), "Cyclist": (0.7, 1.8, 1.6)}
    for _ in range(n_frames):
        g, d, s = [], [], []
        for _ in range(rng.integers(3, 9)):
            name = rng.choice(list(sizes))
            box = [rng.uniform(2, 45), rng.uniform(-15, 15), rng.uniform(-1, 1), *sizes[name], rng.uniform(-3, 3)]
            g.append((name, box))
            if rng.random() < 0.8:  # a noisy detection, sometimes of a confused class
                noisy = np.array(box) + rng.normal(0, [0.4, 0.4, 0.2, 0.1, 0.2, 0.1, 0.2])
                dname = name if rng.random() < 0.85 else rng.choice(["Car", "Pedestrian", "Cyclist"])
                d.append((dname if dname != "Van" else "Car", list(noisy)))
                s.append(rng.uniform(0.2, 1.0))
        for _ in range(rng.integers(0, 4)):  # false positives
            name = rng.choice(["Car", "Pedestrian", "Cyclist"])
            d.append((name, [rng.uniform(2, 45), rng.uniform(-15, 15), 0, *sizes[name], rng.uniform(-3, 3)]))
            s.append(rng.uniform(0, 1))
        gts.append(frame(*g))
        dets.append(frame(*d, scores=s) if d else {"names": [], "boxes": np.zeros((0, 7)), "scores": []})
    return gts, dets


@pytest.mark.skipif(Polygon is None, reason="shapely not installed")
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("region", kitti3d.REGIONS)
def test_ap_matches_the_loop_by_loop_reference(seed, region):
    gts, dets = random_scene(np.random.default_rng(seed))
    ours = kitti3d.evaluate(gts, dets, kitti3d.VOD_IOU, region)
    for cls, thr in kitti3d.VOD_IOU.items():
        if ours["num_gt"][cls]:
            assert ours["AP"][cls] == pytest.approx(reference_ap(gts, dets, cls, thr, region), abs=1e-9), cls
    assert any(0 < ap < 100 for ap in ours["AP"].values())  # the scenes exercise partial matches


def test_score_thresholds_sample_recall_in_fortieths():
    # 80 true positives over 80 ground truths: every other score, 41 thresholds
    t = kitti3d.score_thresholds(np.linspace(1, 0.01, 80), 80)
    assert len(t) == 41 and t[0] == 1.0
    assert len(kitti3d.score_thresholds([0.5, 0.4], 4)) == 2

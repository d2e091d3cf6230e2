"""VoD / KITTI 3D AP: hand-computed cases and a loop-by-loop reference with shapely IoU.

The reference (below) computes its own ignore flags from the raw inputs (camera-frame corridor,
neighbour classes, 40 px heights given or projected), transcribing VoD's clean_data; it calls
nothing of the implementation but `evaluate`, which it is compared with."""

import math

import numpy as np
import pytest

from dsfec_jax.boxes.structures import Boxes
from dsfec_jax.core.grid import VOD_GRID
from dsfec_jax.metrics import kitti3d

try:
    from shapely.geometry import Polygon
except ImportError:  # pragma: no cover - shapely is a dev dependency
    Polygon = None


def car(x, y, yaw=0.0, z=0.0, cls="Car", size=(1.8, 4.2, 1.5)):
    return cls, [x, y, z, *size, yaw]


def level_camera(tx=0.0, ty=0.0, tz=0.0):
    """Radar (x fwd, y left, z up) -> camera (x right, y down, z fwd), level, camera = radar + t."""
    return np.array([[0, -1, 0, tx], [0, 0, -1, ty], [1, 0, 0, tz], [0, 0, 0, 1]], float)


def frame(*boxes, scores=None, **camera):
    out = {"names": [b[0] for b in boxes], "boxes": np.array([b[1] for b in boxes]).reshape(-1, 7), **camera}
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
    cam = {"cam_from_sensor": level_camera()}
    gts = [frame(car(10, 0), car(10, 8), **cam)]
    dets = [frame(car(10, 8), car(30, 0), car(10, 0), scores=[0.9, 0.85, 0.8], **cam)]
    entire = kitti3d.evaluate(gts, dets, {"Car": 0.5}, "entire")
    corridor = kitti3d.evaluate(gts, dets, {"Car": 0.5}, "corridor")
    assert entire["num_gt"]["Car"] == 2 and corridor["num_gt"]["Car"] == 1
    # corridor: the y = 8 and x = 30 boxes are ignored, leaving one perfect match
    assert corridor["AP"]["Car"] == pytest.approx(100 / 11)
    assert set(kitti3d.evaluate_vod(gts, dets, {"Car": 0.5})) == {"entire", "corridor"}


def test_the_corridor_is_measured_in_the_camera_frame():
    # VoD's camera sits ~1.44 m behind the radar: radar x = 24 is camera z = 25.44, past the 25 m
    # corridor; radar y = -3.95, with the camera 0.1 m to the radar's left, is camera x = 4.05, beside it
    cam = {"cam_from_sensor": level_camera(tx=0.1, tz=1.44)}
    gts = [frame(car(10, 0), car(24, 0), car(10, -3.95), **cam)]
    dets = [frame(car(10, 0), car(24, 0), car(10, -3.95), scores=[0.9, 0.8, 0.7], **cam)]
    corridor = kitti3d.evaluate(gts, dets, {"Car": 0.5}, "corridor")
    assert corridor["num_gt"]["Car"] == 1 and corridor["AP"]["Car"] == pytest.approx(100 / 11)
    np.testing.assert_allclose(kitti3d.camera_locations(gts[0]["boxes"], cam["cam_from_sensor"])[1],
                               [0.1, 0.75, 25.44])  # bottom centre: camera y points down
    with pytest.raises(ValueError, match="ground truth frame 0.*cam_from_sensor"):
        kitti3d.evaluate([frame(car(10, 0))], [frame(scores=[])], {"Car": 0.5}, "corridor")


def test_out_of_corridor_detections_of_any_class_are_ignored():
    # VoD's clean_data ignores a detection outside the corridor whatever its class: for Car, the
    # Pedestrian-named box beyond 25 m is then a candidate that takes the car's match (the highest
    # score wins the threshold pass) without being a true positive; in the entire area it is no
    # Car detection at all and the car is found.
    cam = {"cam_from_sensor": level_camera()}
    gts = [frame(car(24.8, 0), **cam)]
    dets = [frame(car(25.2, 0, cls="Pedestrian"), car(24.8, 0), scores=[0.9, 0.5], **cam)]  # 3D IoU 0.83
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5}, "entire")["AP"]["Car"] == pytest.approx(100 / 11)
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5}, "corridor")["AP"]["Car"] == 0.0


def test_the_40_px_rule_on_given_and_projected_heights():
    gts = [frame(car(10, 0), car(20, 0), car(30, 0))]
    gts[0]["bbox_height"] = [40.0, 40.1, 200.0]  # ground truth at <= 40 px is ignored
    dets = [frame(car(10, 0), car(20, 0), car(40, 0), scores=[0.9, 0.8, 0.95])]
    dets[0]["bbox_height"] = [100.0, 100.0, 39.9]  # a detection under 40 px is ignored, not a false positive
    res = kitti3d.evaluate(gts, dets, {"Car": 0.5})
    assert res["num_gt"]["Car"] == 2 and res["curves"]["Car"]["precision"][0] == 1.0
    # projected: a 1.5 m tall box 20 m ahead (nearest face at 18 m) spans 2 * 1000 * 0.75 / 18 px
    p2 = np.array([[1000.0, 0, 960, 0], [0, 1000.0, 600, 0], [0, 0, 1, 0]])
    box = np.array([[20.0, 0, 0, 1.8, 4.0, 1.5, 0]])
    h = kitti3d.projected_heights(box, level_camera(), p2, (1920, 1200))
    assert h[0] == pytest.approx(1500 / 18)
    row_0 = p2.copy()
    row_0[1, 2] = 0.0  # principal point on the image's top row: the image clips the box's upper half
    assert kitti3d.projected_heights(box, level_camera(), row_0, (1920, 1200))[0] == pytest.approx(750 / 18)
    # the detections with a camera instead of given heights (f = 600 px): at 40 m the car projects
    # to 2 * 600 * 0.75 / 38 = 23.7 px and is ignored; at 20 m 50 px
    short = p2 * [[0.6], [0.6], [1]]
    cam = {"cam_from_sensor": level_camera(), "P2": short, "image_size": (1920, 1200)}
    dets = [frame(car(10, 0), car(20, 0), car(40, 0), scores=[0.9, 0.8, 0.95], **cam)]
    assert kitti3d.evaluate(gts, dets, {"Car": 0.5})["curves"]["Car"]["precision"][0] == 1.0
    with pytest.raises(ValueError, match="detections frame 0.*image_size"):
        kitti3d.evaluate(gts, [frame(car(1, 1), scores=[1], P2=p2)])


def test_zero_frames_are_an_error_not_a_score():
    with pytest.raises(ValueError, match="no frames"):
        kitti3d.evaluate([], [])
    with pytest.raises(ValueError, match="no frames"):
        kitti3d.evaluate_vod([], [])


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


def reference_location(box, m):
    """Camera-frame bottom centre, one matrix row at a time (KITTI's label `location`)."""
    bottom = [box[0], box[1], box[2] - box[5] / 2]
    return [sum(m[r][k] * bottom[k] for k in range(3)) + m[r][3] for r in range(3)]


def reference_height(box, m, p2, image_size):
    """Image-box height: the 8 corners through camera and P2, top and bottom clipped to the image."""
    x, y, z, w, l, h, yaw = box
    vs = []
    for dl in (-1, 1):
        for dw in (-1, 1):
            for dh in (-1, 1):
                corner = [x + dl * l / 2 * math.cos(yaw) - dw * w / 2 * math.sin(yaw),
                          y + dl * l / 2 * math.sin(yaw) + dw * w / 2 * math.cos(yaw), z + dh * h / 2]
                cam = [sum(m[r][k] * corner[k] for k in range(3)) + m[r][3] for r in range(3)]
                u = [sum(p2[r][k] * cam[k] for k in range(3)) + p2[r][3] for r in range(3)]
                vs.append(u[1] / u[2])
    return min(max(vs), image_size[1]) - max(min(vs), 0.0)


def reference_flags(gt, det, cls, region):
    """VoD's clean_data, one box at a time, from the raw frame entries."""
    cls = cls.lower()
    neighbour = {"car": "van", "pedestrian": "person_sitting"}.get(cls)

    def outside(box, f):
        if region != "corridor":
            return False
        x, _, z = reference_location(box, f["cam_from_sensor"])
        return x < -4.0 or x > 4.0 or z > 25.0

    def height(i, f):
        if "bbox_height" in f:
            return f["bbox_height"][i]
        if "P2" in f:
            return reference_height(f["boxes"][i], f["cam_from_sensor"], f["P2"], f["image_size"])
        return None

    ignored_gt = []
    for i, (name, box) in enumerate(zip(gt["names"], gt["boxes"])):
        name = name.lower()
        valid_class = 1 if name == cls else 0 if name == neighbour else -1
        h = height(i, gt)
        ignore = (h is not None and h <= 40) or outside(box, gt)
        if valid_class == 1 and not ignore:
            ignored_gt.append(0)
        elif valid_class == 0 or (ignore and valid_class == 1):
            ignored_gt.append(1)
        else:
            ignored_gt.append(-1)
    ignored_det = []
    for i, (name, box) in enumerate(zip(det["names"], det["boxes"])):
        h = height(i, det)
        if h is not None and h < 40:
            ignored_det.append(1)
        elif outside(box, det):
            ignored_det.append(1)
        elif name.lower() == cls:
            ignored_det.append(0)
        else:
            ignored_det.append(-1)
    return ignored_gt, ignored_det


def reference_ap(gts, dets, cls, min_overlap, region):
    prepared, num_gt, all_scores = [], 0, []
    for gt, det in zip(gts, dets):
        ig, idt = reference_flags(gt, det, cls, region)
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


def random_camera(rng):
    """A radar -> camera transform like VoD's or TJ4D's: axes swapped, tilted a few degrees, offset."""
    pitch, yaw = rng.uniform(-0.1, 0.1), rng.uniform(-0.03, 0.03)
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    tilt = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    m = np.eye(4)
    m[:3, :3] = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]]) @ tilt
    m[:3, 3] = [rng.uniform(-0.2, 0.2), rng.uniform(0.5, 1.5), rng.uniform(0, 3)]
    return m


def random_scene(rng, n_frames=8):
    """Frames with a random camera each; ground truth with given 2D heights in half the frames,
    detections projected through a P2 (f 500-900 px: far pedestrians fall under 40 px) in half."""
    gts, dets = [], []
    sizes = {"Car": (1.8, 4.2, 1.5), "Van": (2.0, 5.0, 2.0), "Pedestrian": (0.6, 0.8, 1.7), "Cyclist": (0.7, 1.8, 1.6),
             "Person_sitting": (0.6, 0.8, 1.2)}
    for k in range(n_frames):
        g, d, s = [], [], []
        for _ in range(rng.integers(4, 11)):
            name = rng.choice(list(sizes))
            box = [rng.uniform(2, 35), rng.uniform(-7, 7), rng.uniform(-1, 1), *sizes[name], rng.uniform(-3, 3)]
            g.append((name, box))
            if rng.random() < 0.8:  # a noisy detection, sometimes of a confused class
                noisy = np.array(box) + rng.normal(0, [0.4, 0.4, 0.2, 0.1, 0.2, 0.1, 0.2])
                dname = name if rng.random() < 0.85 else rng.choice(["Car", "Pedestrian", "Cyclist"])
                d.append((dname if dname in ("Car", "Pedestrian", "Cyclist") else "Car", list(noisy)))
                s.append(rng.uniform(0.2, 1.0))
        for _ in range(rng.integers(0, 4)):  # false positives
            name = rng.choice(["Car", "Pedestrian", "Cyclist"])
            d.append((name, [rng.uniform(2, 45), rng.uniform(-8, 8), 0, *sizes[name], rng.uniform(-3, 3)]))
            s.append(rng.uniform(0, 1))
        cam = {"cam_from_sensor": random_camera(rng)}
        gt = frame(*g, **cam)
        if k % 2:
            gt["bbox_height"] = rng.choice([30.0, 40.0, 40.5, 120.0, 150.0, 200.0], len(g))
        det_cam = dict(cam)
        if k in (0, 1, 2, 4):  # frame 1 has both sides measured, 3 and 5 ground truth only
            f = rng.uniform(500, 900)
            det_cam.update(P2=np.array([[f, 0, 968, 0], [0, f, 608, 0], [0, 0, 1, 0]]), image_size=(1936, 1216))
        empty = {"names": [], "boxes": np.zeros((0, 7)), "scores": [], **det_cam}
        dets.append(frame(*d, scores=s, **det_cam) if d else empty)
        gts.append(gt)
    return gts, dets


VOD_CLASSES = {"Car": 0.5, "Pedestrian": 0.25, "Cyclist": 0.25}


@pytest.mark.skipif(Polygon is None, reason="shapely not installed")
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("region", ["entire", "corridor"])
def test_ap_matches_the_loop_by_loop_reference(seed, region):
    gts, dets = random_scene(np.random.default_rng(seed))
    ours = kitti3d.evaluate(gts, dets, VOD_CLASSES, region)
    for cls, thr in VOD_CLASSES.items():
        if ours["num_gt"][cls]:
            assert ours["AP"][cls] == pytest.approx(reference_ap(gts, dets, cls, thr, region), abs=1e-9), cls
    assert any(0 < ap < 100 for ap in ours["AP"].values())  # the scenes exercise partial matches
    flags = [reference_flags(g, d, "Car", region) for g, d in zip(gts, dets)]
    assert any(1 in ig for ig, _ in flags) and any(1 in idt for _, idt in flags)  # and ignored boxes on both sides


def test_score_thresholds_sample_recall_in_fortieths():
    # 80 true positives over 80 ground truths: every other score, 41 thresholds
    t = kitti3d.score_thresholds(np.linspace(1, 0.01, 80), 80)
    assert len(t) == 41 and t[0] == 1.0
    assert len(kitti3d.score_thresholds([0.5, 0.4], 4)) == 2


# ---------------------------------------------------------------------------------------------
# evaluate.score_vod: the protocol on Frames (real VoD frames carry their calibration and labels)

def vod_frames(shared_data):
    from dsfec_jax.data.points.sources import load_frames

    frames = load_frames(f"vod:{shared_data / 'vod' / 'example_set'}", "all", features="native")
    return [frames[i] for i in range(len(frames))]


def as_detections(frames, extra=None):
    """Every ground-truth box as a detection (score 0.9), plus `extra` boxes in the first frame (0.99)."""
    from dsfec_jax.modalities.points.predict import Detections

    out = {f.frame_id: Detections(f.boxes, np.full(len(f.boxes), 0.9)) for f in frames}
    if extra is not None:
        b = frames[0].boxes
        fields = ("center", "size", "yaw", "velocity", "names")
        joined = Boxes(*(np.concatenate([getattr(b, k), getattr(extra, k)]) for k in fields))
        out[frames[0].frame_id] = Detections(joined, np.r_[np.full(len(b), 0.9), np.full(len(extra), 0.99)])
    return out


VOD_HEADS = ("pedestrian", "bicycle", "car")


def test_score_vod_on_real_vod_frames_follows_the_official_classes_and_corridor(shared_data):
    from dsfec_jax.modalities.points.evaluate import score_vod

    frames = vod_frames(shared_data)
    res = score_vod(frames, as_detections(frames), VOD_GRID, VOD_HEADS)
    # 8 Cyclists; the 15 parked VoD 'bicycle's are no class of VoD's evaluation
    assert res["num_gt"] == {"pedestrian": 16, "bicycle": 8, "car": 1}
    # camera-frame corridor: the car at radar y = -4.03 is at camera x = 3.99 (inside), a
    # pedestrian at radar y = +3.99 at camera x = -4.07 (outside)
    assert res["num_gt_corridor"] == {"pedestrian": 6, "bicycle": 5, "car": 1}


def test_score_vod_applies_the_40_px_rule_to_real_vod_frames(shared_data):
    import dataclasses

    from dsfec_jax.modalities.points.evaluate import score_vod

    frames = vod_frames(shared_data)
    perfect = score_vod(frames, as_detections(frames), VOD_GRID, VOD_HEADS)
    # a detection 0.3 m tall at 20 m projects to ~21 px: ignored, not a false positive
    tiny = Boxes(np.array([[20.0, -10.0, 0.0]], np.float32), np.array([[0.6, 0.8, 0.3]], np.float32),
                 np.zeros(1, np.float32), np.zeros((1, 2), np.float32), np.array(["pedestrian"]))
    with_tiny = score_vod(frames, as_detections(frames, tiny), VOD_GRID, VOD_HEADS)
    assert with_tiny["AP"] == perfect["AP"]
    tall = dataclasses.replace(tiny, size=np.array([[0.6, 0.8, 1.7]], np.float32))  # ~117 px: a false positive
    with_tall = score_vod(frames, as_detections(frames, tall), VOD_GRID, VOD_HEADS)
    assert with_tall["AP"]["pedestrian"] < perfect["AP"]["pedestrian"]
    # ground truth reads its label's 2D box: a pedestrian label 30 px tall leaves the count
    f = frames[0]
    labels = f.meta["kitti_labels"]
    ped = int(np.flatnonzero(f.boxes.names == "pedestrian")[0])
    bbox = labels.bbox.copy()
    bbox[ped, 3] = bbox[ped, 1] + 30
    frames[0] = dataclasses.replace(f, meta={**f.meta, "kitti_labels": dataclasses.replace(labels, bbox=bbox)})
    assert score_vod(frames, as_detections(frames), VOD_GRID, VOD_HEADS)["num_gt"]["pedestrian"] == 15


def test_score_vod_cameras_by_source(shared_data):
    from dsfec_jax.data.points import kitti
    from dsfec_jax.data.points.sources import load_frames
    from dsfec_jax.modalities.points.evaluate import _camera

    vod = vod_frames(shared_data)[0]
    assert set(_camera(vod)) == {"cam_from_sensor", "P2", "image_size"}
    tj4d = load_frames(f"tj4d:{shared_data / 'tj4dradset' / 'Sample'}", "all", 1, features="native")[0]
    assert set(_camera(tj4d)) == {"cam_from_sensor"}  # TJ4D's own evaluation has no 40 px rule
    np.testing.assert_allclose(_camera(tj4d)["cam_from_sensor"], tj4d.meta["calib"].cam_from_sensor())
    synthetic = load_frames("synthetic4d", "val", 1, features="native")[0]
    np.testing.assert_allclose(_camera(synthetic)["cam_from_sensor"][:3], kitti.VOD_RADAR_TO_CAMERA)


def test_score_vod_of_zero_frames_is_an_error():
    from dsfec_jax.modalities.points.evaluate import score_vod

    with pytest.raises(ValueError, match="no frames"):
        score_vod([], {}, VOD_GRID, VOD_HEADS)

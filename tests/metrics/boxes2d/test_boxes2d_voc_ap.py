"""VOC AP (metrics.boxes2d.voc_ap) and VOC <-> COCO JSON (metrics.boxes2d.voc_coco).

Oracles:
- the toy test_case_1 of rafaelpadilla/review_object_detection_metrics (its PROVENANCE.md: 8 APs);
  its convention is voc_eval's "+1" formula applied to (x, y, x + w, y + h), i.e.
  convention="inclusive" on those numbers, IoU >= threshold, score ties in file order;
- hand-computed cases for each voc_eval rule under the defaults;
- on the 100 real VOC images, an independent transcription of voc_eval (raw file numbers, "+1",
  parsed here with ElementTree and str.split) against the reader + voc_ap path.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import shared_data_dir

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.camera import voc
from dsfec_jax.metrics.boxes2d.coco_json import coco_dets_from_list, coco_dets_to_list, default_category_ids
from dsfec_jax.metrics.boxes2d.voc_ap import average_precision, voc_ap
from dsfec_jax.metrics.boxes2d.voc_coco import load_voc_gt_from_coco, voc_gt_from_coco, voc_gt_to_coco

TOY_IOUS = (0.1, 0.3, 0.5, 0.75)
TOY_VOC07 = (0.3333333333, 0.2683982683, 0.0303030303, 0.0)
TOY_ALL = (0.3371980676, 0.2456866804, 0.0222222222, 0.0)


@pytest.fixture(scope="module")
def padilla():
    path = shared_data_dir() / "voc_review_od_metrics"
    if not (path / "tests" / "test_case_1" / "gts").is_dir():
        pytest.fail(f"VOC oracle data not found under {path}; set DSFEC_DATA")
    return path


def gt(voc_xyxy, names, difficult=None) -> Boxes2D:
    """Ground truth from VOC 1-based inclusive numbers, through the reader's conversion."""
    return Boxes2D(voc.inclusive_to_edges(voc_xyxy).astype(np.float32), np.array(names),
                   difficult=None if difficult is None else np.array(difficult, bool))


def det(voc_xyxy, names, scores) -> Boxes2D:
    return Boxes2D(voc.inclusive_to_edges(voc_xyxy).astype(np.float32), np.array(names),
                   np.array(scores, np.float32))


def one_class_ap(gts, dets, **kw) -> float:
    """AP of class "a", rounded to 1e-12: voc_eval's 11-point sum of p / 11 makes a perfect AP
    1.0000000000000002, and so does ours."""
    return round(float(voc_ap(gts, dets, ["a"], **kw).ap[0]), 12)


# --------------------------------------------------------------------------- the toy oracle


def toy_frames(root, kind: str) -> dict[str, Boxes2D]:
    """test_case_1: `class [score] x y w h` -> (x, y, x + w, y + h), as Padilla's converter reads it."""
    frames = {}
    for path in sorted((root / "tests" / "test_case_1" / kind).glob("*.txt")):
        rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
        xywh = np.array([[float(v) for v in r[-4:]] for r in rows])
        frames[path.stem] = Boxes2D(np.concatenate([xywh[:, :2], xywh[:, :2] + xywh[:, 2:]], 1).astype(np.float32),
                                    np.array([r[0] for r in rows]),
                                    np.array([float(r[1]) for r in rows], np.float32) if kind == "dets" else None)
    return frames


def test_the_toy_oracle_of_padilla(padilla):
    gts, dets = toy_frames(padilla, "gts"), toy_frames(padilla, "dets")
    assert sum(map(len, gts.values())) == 15 and sum(map(len, dets.values())) == 24
    for iou, want07, want_all in zip(TOY_IOUS, TOY_VOC07, TOY_ALL):
        for metric, want in (("voc07", want07), ("all", want_all)):
            got = voc_ap(gts, dets, ["object"], iou_threshold=iou, metric=metric, convention="inclusive", strict=False)
            assert got.map == pytest.approx(want, abs=1e-6), (iou, metric)
    # the "+1" is what reproduces it: plain edge IoU gives other numbers at IoU 0.1 and 0.3
    plain = voc_ap(gts, dets, ["object"], iou_threshold=0.1, metric="all", strict=False)
    assert abs(plain.map - TOY_ALL[0]) > 0.05


# --------------------------------------------------------------------------- voc_eval's rules, by hand


def test_a_match_needs_iou_strictly_above_the_threshold():
    # VOC (1, 1, 10, 10) is 10 x 10 pixels, (1, 1, 10, 20) 10 x 20: voc_eval's IoU = 100 / 200 = 0.5 exactly
    gts, dets = {"i": gt([[1, 1, 10, 10]], ["a"])}, {"i": det([[1, 1, 10, 20]], ["a"], [0.9])}
    assert one_class_ap(gts, dets) == 0.0                      # 0.5 > 0.5 is false: a false positive
    assert one_class_ap(gts, dets, strict=False) == 1.0        # >= would match
    assert one_class_ap(gts, dets, iou_threshold=0.49) == 1.0


def test_widths_count_pixels_plus_one():
    # VOC (1, 1, 2, 2) and (2, 1, 3, 2): 2 x 2 pixels each, sharing one column: voc_eval IoU 2 / 6 = 1/3
    raw_gt, raw_det = [[1, 1, 2, 2]], [[2, 1, 3, 2]]
    gts, dets = {"i": gt(raw_gt, ["a"])}, {"i": det(raw_det, ["a"], [0.9])}
    assert one_class_ap(gts, dets, iou_threshold=0.33) == 1.0 and one_class_ap(gts, dets, iou_threshold=0.34) == 0.0
    # the same numbers taken verbatim with voc_eval's +1 formula agree; without any +1 they do not overlap
    raw = ({"i": Boxes2D(np.array(raw_gt, np.float32), np.array(["a"]))},
           {"i": Boxes2D(np.array(raw_det, np.float32), np.array(["a"]), np.array([0.9], np.float32))})
    assert one_class_ap(*raw, iou_threshold=0.33, convention="inclusive") == 1.0
    assert one_class_ap(*raw, iou_threshold=0.0, strict=False, convention="edges") == 1.0  # IoU 0 >= 0
    assert one_class_ap(*raw, iou_threshold=0.0, convention="edges") == 0.0


def test_a_difficult_match_is_neither_tp_nor_fp():
    gts = {"i": gt([[1, 1, 10, 10], [50, 50, 60, 60]], ["a", "a"], [False, True])}
    dets = {"i": det([[50, 50, 60, 60], [1, 1, 10, 10], [100, 100, 110, 110]], ["a"] * 3, [0.9, 0.8, 0.7])}
    result = voc_ap(gts, dets, ["a"], metric="all")
    assert result.npos.tolist() == [1] and result.ap[0] == 1.0  # ignored, TP, FP: rec 0, 1, 1; prec 0, 1, 1/2
    assert one_class_ap(gts, dets) == 1.0
    removed = {"i": gt([[1, 1, 10, 10]], ["a"])}                # without the difficult box: FP, TP, FP
    assert one_class_ap(removed, dets, metric="all") == 0.5


def test_a_second_match_to_a_difficult_box_is_ignored_too():
    # voc_eval never marks a difficult box as taken: every match to it, the first or a later one, is
    # neither TP nor FP (a second match to a non-difficult box is an FP: the next test)
    gts = {"i": gt([[1, 1, 10, 10], [50, 50, 60, 60]], ["a", "a"], [False, True])}
    dets = {"i": det([[50, 50, 60, 60], [50, 50, 60, 61], [1, 1, 10, 10]], ["a"] * 3, [0.9, 0.8, 0.7])}
    result = voc_ap(gts, dets, ["a"], metric="all")  # ignored, ignored, TP: precision 1 at recall 1
    assert result.npos.tolist() == [1] and result.n_det.tolist() == [3] and result.ap[0] == 1.0
    assert one_class_ap(gts, dets) == 1.0


def test_only_the_best_iou_ground_truth_is_considered():
    # the detection's best ground truth is the difficult one: it is ignored although it also
    # overlaps a non-difficult ground truth by IoU 100/120 > 0.5, which stays unmatched
    gts = {"i": gt([[1, 1, 10, 12], [1, 1, 10, 10]], ["a", "a"], [False, True])}
    dets = {"i": det([[1, 1, 10, 10]], ["a"], [0.9])}
    assert one_class_ap(gts, dets) == 0.0 and one_class_ap(gts, dets, metric="all") == 0.0


def test_a_second_match_is_a_false_positive_and_the_two_metrics_differ():
    gts = {"i": gt([[1, 1, 10, 10]], ["a"]), "j": gt([[1, 1, 10, 10]], ["a"])}
    dets = {"i": det([[1, 1, 10, 10], [1, 1, 10, 11]], ["a", "a"], [0.9, 0.8]),
            "j": det([[1, 1, 10, 10]], ["a"], [0.7])}
    # TP, FP (the same ground truth again), TP: recall 1/2, 1/2, 1; precision 1, 1/2, 2/3
    assert one_class_ap(gts, dets, metric="all") == pytest.approx(0.5 * 1 + 0.5 * 2 / 3)
    assert one_class_ap(gts, dets, metric="voc07") == pytest.approx((6 * 1 + 5 * 2 / 3) / 11)


def test_voc07_keeps_voc_evals_float_recall_points():
    # 10 ground truths, 3 found: recall 0.1, 0.2, 0.3 at precision 1. np.arange(0, 1.1, 0.1)[3] is
    # 0.30000000000000004 > 3/10, so voc_eval counts 3 of the 11 points, not 4
    boxes = [[10 * k + 1, 1, 10 * k + 5, 5] for k in range(10)]
    gts, dets = {"i": gt(boxes, ["a"] * 10)}, {"i": det(boxes[:3], ["a"] * 3, [0.9, 0.8, 0.7])}
    assert one_class_ap(gts, dets, metric="voc07") == pytest.approx(3 / 11, abs=1e-12)  # not 4 / 11
    assert one_class_ap(gts, dets, metric="all") == pytest.approx(0.3, abs=1e-12)


def test_classes_without_ground_truth_are_nan_and_left_out_of_the_map():
    gts = {"i": gt([[1, 1, 10, 10]], ["a"]), "j": gt([[1, 1, 10, 10]], ["b"], [True])}
    dets = {"i": det([[1, 1, 10, 10]], ["a"], [0.9]), "j": det([[1, 1, 10, 10]], ["c"], [0.5])}
    result = voc_ap(gts, dets, ["a", "b", "c", "d"])
    assert result.ap[0] == pytest.approx(1.0) and np.isnan(result.ap[1:]).all() and result.npos.tolist() == [1, 0, 0, 0]
    assert result.map == pytest.approx(1.0) and result.n_det.tolist() == [1, 0, 1, 0]
    assert result.as_dict()["classes"]["b"] == {"ap": None, "npos": 0, "n_det": 0}
    none = voc_ap({"i": gt([[1, 1, 10, 10]], ["a"])}, {}, ["a", "b"])  # ground truth, no detection: 0
    assert none.ap[0] == 0.0 and none.map == 0.0
    assert np.isnan(voc_ap({"i": Boxes2D.empty()}, {}, ["a"]).map)


def test_detections_of_an_unknown_image_or_class_are_errors():
    with pytest.raises(ValueError, match="without ground truth"):
        voc_ap({"i": Boxes2D.empty()}, {"k": det([[1, 1, 2, 2]], ["a"], [0.5])}, ["a"])
    with pytest.raises(ValueError, match="class 'z'"):
        voc_ap({"i": Boxes2D.empty()}, {"i": det([[1, 1, 2, 2]], ["z"], [0.5])}, ["a"])
    with pytest.raises(ValueError, match="metric"):
        voc_ap({}, {}, ["a"], metric="coco")


def test_average_precision_of_voc_ap_by_hand():
    rec, prec = np.array([0.25, 0.5, 0.5, 0.75]), np.array([1.0, 1.0, 2 / 3, 0.75])
    assert average_precision(rec, prec, "all") == pytest.approx(0.5 + 0.25 * 0.75)
    assert average_precision(rec, prec, "voc07") == pytest.approx((6 + 2 * 0.75) / 11)  # t = 0 .. 0.5, then 0.6, 0.7
    assert average_precision(np.zeros(0), np.zeros(0), "voc07") == 0.0 == average_precision([], [], "all")


# --------------------------------------------------------------------------- the 100 real VOC images


def voc_eval_transcription(database, names, class_name: str, use_07: bool) -> float:
    """voc_eval's loop, written out here on the files' raw numbers (no project reader)."""
    recs = {}
    for path in sorted((database / "gts" / "pascalvoc_format").glob("*.xml")):
        objs = [o for o in ET.parse(path).findall("object") if o.find("name").text == class_name]
        bbox = np.array([[float(o.find("bndbox").find(k).text) for k in ("xmin", "ymin", "xmax", "ymax")]
                         for o in objs]).reshape(-1, 4)
        difficult = np.array([int(o.find("difficult").text) if o.find("difficult") is not None else 0
                              for o in objs], bool)
        recs[path.stem] = {"bbox": bbox, "difficult": difficult, "det": [False] * len(objs)}
    npos = sum(int((~r["difficult"]).sum()) for r in recs.values())
    lines = [(path.stem, *map(float, line.split()[1:]))
             for path in sorted((database / "dets" / "abs_xyx2y2").glob("*.txt"))
             for line in path.read_text().splitlines() if line.strip() and names[int(line.split()[0])] == class_name]
    order = np.argsort(-np.array([line[1] for line in lines]), kind="stable")
    tp, fp = np.zeros(len(lines)), np.zeros(len(lines))
    for d, k in enumerate(order):
        image, _, *bb = lines[k]
        r = recs[image]
        ovmax, jmax = -np.inf, -1
        if len(r["bbox"]):
            g = r["bbox"]
            iw = np.maximum(np.minimum(g[:, 2], bb[2]) - np.maximum(g[:, 0], bb[0]) + 1.0, 0.0)
            ih = np.maximum(np.minimum(g[:, 3], bb[3]) - np.maximum(g[:, 1], bb[1]) + 1.0, 0.0)
            inter = iw * ih
            overlaps = inter / ((bb[2] - bb[0] + 1.0) * (bb[3] - bb[1] + 1.0)
                                + (g[:, 2] - g[:, 0] + 1.0) * (g[:, 3] - g[:, 1] + 1.0) - inter)
            ovmax, jmax = overlaps.max(), overlaps.argmax()
        if ovmax > 0.5:
            if not r["difficult"][jmax]:
                if not r["det"][jmax]:
                    tp[d], r["det"][jmax] = 1.0, True
                else:
                    fp[d] = 1.0
        else:
            fp[d] = 1.0
    tp, fp = np.cumsum(tp), np.cumsum(fp)
    rec, prec = tp / npos, tp / np.maximum(tp + fp, np.finfo(np.float64).eps)
    if use_07:
        return sum((prec[rec >= t].max() if (rec >= t).any() else 0.0) / 11.0 for t in np.arange(0.0, 1.1, 0.1))
    mrec, mpre = np.concatenate(([0.0], rec, [1.0])), np.concatenate(([0.0], prec, [0.0]))
    for i in range(len(mpre) - 1, 0, -1):
        mpre[i - 1] = max(mpre[i - 1], mpre[i])
    i = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[i + 1] - mrec[i]) * mpre[i + 1]))


@pytest.fixture(scope="module")
def database(padilla):
    return padilla / "data" / "database"


@pytest.fixture(scope="module")
def real(database):
    names = voc.read_names(database / "voc.names")
    gts = {sid: a.boxes() for sid, a in voc.read_annotation_dir(database / "gts" / "pascalvoc_format").items()}
    dets = {sid: voc.detection_boxes(d)
            for sid, d in voc.read_detection_dir(database / "dets" / "abs_xyx2y2", names).items()}
    return names, gts, dets


@pytest.mark.parametrize("metric", ["voc07", "all"])
def test_real_voc_per_class_ap_equals_an_independent_voc_eval(database, real, metric):
    names, gts, dets = real
    result = voc_ap(gts, dets, names, metric=metric)
    want = [voc_eval_transcription(database, names, c, metric == "voc07") for c in names]
    np.testing.assert_allclose(result.ap, want, rtol=0, atol=1e-12)
    assert result.npos.sum() == 273 - 38 and result.n_det.sum() == 452 and 0 < result.map < 1


# --------------------------------------------------------------------------- COCO JSON


def test_voc_ground_truth_survives_a_coco_json_round_trip(real):
    names, gts, dets = real
    data = json.loads(json.dumps(voc_gt_to_coco(gts, names)))
    assert len(data["annotations"]) == 273 and sum(a["iscrowd"] for a in data["annotations"]) == 38
    back = voc_gt_from_coco(data)
    assert list(back) == list(gts)
    for sid, boxes in gts.items():
        np.testing.assert_array_equal(back[sid].xyxy, boxes.xyxy)
        assert back[sid].names.tolist() == boxes.names.tolist()
        assert back[sid].difficult.tolist() == boxes.difficult.tolist()
    # detections go through coco_json as they are, and score the same afterwards
    image_ids = {str(i["file_name"]): i["id"] for i in data["images"]}
    results = json.loads(json.dumps(coco_dets_to_list(dets, default_category_ids(names), image_ids)))
    dets_back = coco_dets_from_list(results, default_category_ids(names), image_ids)
    assert voc_ap(back, dets_back, names).map == voc_ap(gts, dets, names).map


def test_cvats_coco_export_puts_voc_numbers_on_edges(padilla, real):
    """The repository's CVAT export of the same XMLs writes bbox (xmin, ymin, xmax - xmin, ...): read
    as edges, its boxes are the XML's raw numbers, one pixel off the reader's (xmin - 1, ymin - 1)."""
    _, gts, _ = real
    cvat = load_voc_gt_from_coco(padilla / "data" / "database" / "gts" / "coco_format_v1" / "instances_default.json")
    assert set(cvat) == set(gts)
    for sid, boxes in gts.items():
        key = lambda b: sorted(zip(b.names.tolist(), map(tuple, np.asarray(b.xyxy).tolist())))  # noqa: E731
        assert key(cvat[sid]) == key(Boxes2D(voc.edges_to_inclusive(boxes.xyxy).astype(np.float32), boxes.names))

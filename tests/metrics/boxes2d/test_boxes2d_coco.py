"""COCO JSON conversion and the pycocotools COCO AP (metrics.boxes2d.coco_json, metrics.boxes2d.coco).

The oracle: rafaelpadilla/review_object_detection_metrics' COCO test data (a COCO val2014 subset and
734 detections) with the 12 COCOeval numbers of its PROVENANCE.md, reproduced THROUGH the project's
conversion (JSON -> Boxes2D per image -> COCO JSON -> pycocotools).
"""

from __future__ import annotations

import contextlib
import copy
import io
import json

import numpy as np
import pytest
from conftest import shared_data_dir
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.metrics.boxes2d.coco import STAT_NAMES, coco_evaluate
from dsfec_jax.metrics.boxes2d.coco_json import (coco_dets_from_list, coco_dets_to_list, coco_gt_from_dict,
                                                 coco_gt_to_dict, default_image_ids, load_coco_dets, load_coco_gt)

ORACLE = dict(zip(STAT_NAMES, (0.503647, 0.696973, 0.571667, 0.593252, 0.557991, 0.489363,
                               0.386813, 0.593680, 0.595353, 0.654764, 0.603130, 0.553744)))


@pytest.fixture(scope="module")
def oracle_dir():
    path = shared_data_dir() / "voc_review_od_metrics" / "tests" / "test_coco_eval"
    if not (path / "cocoapi_results.json").is_file():
        pytest.fail(f"COCO oracle data not found under {path}; set DSFEC_DATA")
    return path


def boxes(xyxy, names, scores=None) -> Boxes2D:
    return Boxes2D(np.array(xyxy, np.float32).reshape(-1, 4), np.array(names),
                   None if scores is None else np.array(scores, np.float32))


# --------------------------------------------------------------------------- the oracle


def test_coco_oracle_numbers_through_the_conversion(oracle_dir):
    gt = load_coco_gt(oracle_dir / "gts" / "sampled_gts_bbox_area.json")
    dets = load_coco_dets(oracle_dir / "cocoapi_results.json", gt)
    assert len(gt.boxes) == 100 and sum(map(len, gt.boxes.values())) == 830
    assert sum(map(len, dets.values())) == 734 and all(b.scores is not None for b in dets.values())
    m = coco_evaluate(gt, dets)
    assert dict(zip(STAT_NAMES, m.stats)) == pytest.approx(ORACLE, abs=1e-6)
    assert (m.map, m.ap50, m.ap75) == pytest.approx(m.stats[:3], abs=1e-12)
    assert np.nanmean(list(m.per_class_ap.values())) == pytest.approx(m.map, abs=1e-12)
    assert np.nanmean(list(m.per_class_ap50.values())) == pytest.approx(m.ap50, abs=1e-12)


def test_ap30_and_ap70_equal_cocoeval_runs_at_those_thresholds_alone(oracle_dir):
    """The extra 0.3 column neither changes the standard ones nor differs from a run at 0.3 alone."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    gt = load_coco_gt(oracle_dir / "gts" / "sampled_gts_bbox_area.json")
    m = coco_evaluate(gt, load_coco_dets(oracle_dir / "cocoapi_results.json", gt))
    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO(str(oracle_dir / "gts" / "sampled_gts_bbox_area.json"))
        ev = COCOeval(coco_gt, coco_gt.loadRes(str(oracle_dir / "cocoapi_results.json")), "bbox")
        ev.params.iouThrs = np.array([0.3, 0.7])
        ev.evaluate()
        ev.accumulate()
    direct = [p[p > -1].mean() for p in ev.eval["precision"][:, :, :, 0, -1]]
    assert (m.ap30, m.ap70) == pytest.approx(direct, abs=1e-12)
    assert m.ap30 > m.ap50 > m.ap70 > m.ap75


def test_the_oracle_files_survive_a_round_trip(oracle_dir):
    raw = json.loads((oracle_dir / "gts" / "sampled_gts_bbox_area.json").read_text())
    gt = coco_gt_from_dict(raw)
    back = {(a["image_id"], a["category_id"], a["area"]): a["bbox"] for a in gt.to_dict()["annotations"]}
    for a in raw["annotations"]:   # areas exactly as in the file, boxes to float32 precision
        assert back[(a["image_id"], a["category_id"], a["area"])] == pytest.approx(a["bbox"], rel=1e-6, abs=1e-4)
    assert {c["id"]: c["name"] for c in gt.to_dict()["categories"]} == {c["id"]: c["name"] for c in raw["categories"]}


# --------------------------------------------------------------------------- hand-made cases


def test_map_averages_exactly_the_ten_standard_thresholds():
    """IoU 0.62: a hit at 0.30, 0.50, 0.55, 0.60 and a miss from 0.65 on. mAP@[.5:.95] = 3/10
    (4/11 if 0.3 leaked into it)."""
    gts = {"a": boxes([0, 0, 10, 10], ["car"])}
    dets = {"a": boxes([0, 0, 10, 6.2], ["car"], [0.9])}
    m = coco_evaluate(gts, dets, ["car", "person"])
    assert m.map == pytest.approx(0.3, abs=1e-12) and m.stats[0] == pytest.approx(0.3, abs=1e-12)
    assert (m.ap30, m.ap50, m.ap70, m.ap75) == pytest.approx((1.0, 1.0, 0.0, 0.0), abs=1e-12)
    assert m.per_class_ap["car"] == pytest.approx(0.3) and m.per_class_ap50["car"] == pytest.approx(1.0)
    assert np.isnan(m.per_class_ap["person"])       # no ground truth: undefined, not 0


def test_ap30_scores_a_box_that_misses_at_50():
    gts = {"1": boxes([[0, 0, 10, 10], [20, 20, 30, 30]], ["car", "car"]), "2": Boxes2D.empty()}
    dets = {"1": boxes([[0, 0, 10, 4], [20, 20, 30, 30]], ["car", "car"], [0.9, 0.8])}   # IoU 0.4 and 1
    m = coco_evaluate(gts, dets, ["car"])
    assert m.ap30 == pytest.approx(1.0)
    # at 0.5 the first detection is a miss: precision 1/2 at the 51 recall points 0..0.5, 0 above
    assert m.ap50 == pytest.approx(51 * 0.5 / 101, abs=1e-12)
    assert m.ap70 == pytest.approx(m.ap50)


def test_no_detections_and_no_ground_truth():
    gts = {"1": boxes([0, 0, 10, 10], ["car"])}
    empty = coco_evaluate(gts, {}, ["car"])
    assert empty.map == 0.0 and empty.ap30 == 0.0
    nothing = coco_evaluate({"1": Boxes2D.empty()}, {"1": boxes([0, 0, 1, 1], ["car"], [0.5])}, ["car"])
    assert np.isnan(nothing.map) and nothing.stats[0] == -1.0


def test_evaluation_errors_name_the_problem():
    gts = {"1": boxes([0, 0, 10, 10], ["car"])}
    with pytest.raises(ValueError, match="'truck' is not one of"):
        coco_evaluate(gts, {"1": boxes([0, 0, 10, 10], ["truck"], [0.9])}, ["car"])
    with pytest.raises(ValueError, match="sample '2'"):
        coco_evaluate(gts, {"2": boxes([0, 0, 10, 10], ["car"], [0.9])}, ["car"])
    with pytest.raises(ValueError, match="need scores"):
        coco_evaluate(gts, {"1": boxes([0, 0, 10, 10], ["car"])}, ["car"])


def test_gt_round_trip_keeps_ids_areas_and_crowds():
    data = {"images": [{"id": 7}, {"id": 3}],
            "annotations": [{"id": 5, "image_id": 7, "category_id": 12, "bbox": [1.5, 2, 3, 4], "area": 9.0,
                             "iscrowd": 1},
                            {"id": 9, "image_id": 7, "category_id": 4, "bbox": [0, 0, 2, 2]}],
            "categories": [{"id": 12, "name": "truck"}, {"id": 4, "name": "car"}]}
    gt = coco_gt_from_dict(data)
    assert gt.classes == ("car", "truck") and gt.image_ids == {"7": 7, "3": 3}
    assert len(gt.boxes["3"]) == 0 and gt.boxes["3"].scores is None
    np.testing.assert_array_equal(gt.boxes["7"].xyxy, [[1.5, 2, 4.5, 6], [0, 0, 2, 2]])
    assert list(gt.boxes["7"].names) == ["truck", "car"]
    assert gt.areas["7"].tolist() == [9.0, 4.0] and gt.iscrowd["7"].tolist() == [True, False]
    again = coco_gt_from_dict(gt.to_dict())
    assert again.image_ids == gt.image_ids and again.category_ids == gt.category_ids
    for sid in gt.boxes:
        np.testing.assert_array_equal(again.boxes[sid].xyxy, gt.boxes[sid].xyxy)
        np.testing.assert_array_equal(again.areas[sid], gt.areas[sid])
        np.testing.assert_array_equal(again.iscrowd[sid], gt.iscrowd[sid])


def test_detection_round_trip_keeps_order_scores_and_empty_frames():
    category_ids, image_ids = {"car": 3, "person": 1}, {"a": 10, "b": 11}
    dets = {"a": boxes([[0, 0, 1, 1], [2, 2, 5, 6]], ["person", "car"], [0.25, 0.75]), "b": Boxes2D.empty(True)}
    results = coco_dets_to_list(dets, category_ids, image_ids)
    assert results[1] == {"image_id": 10, "category_id": 3, "bbox": [2.0, 2.0, 3.0, 4.0], "score": 0.75}
    back = coco_dets_from_list(results, category_ids, image_ids)
    assert list(back) == ["a", "b"] and len(back["b"]) == 0 and back["b"].scores is not None
    np.testing.assert_array_equal(back["a"].xyxy, dets["a"].xyxy)
    np.testing.assert_array_equal(back["a"].scores, dets["a"].scores)
    assert list(back["a"].names) == ["person", "car"]


def test_sample_ids_become_image_ids():
    assert default_image_ids(["12", "3"]) == {"12": 12, "3": 3}
    assert default_image_ids(["012", "3"]) == {"012": 1, "3": 2}        # not canonical: numbered
    assert default_image_ids(["scene-1/0004", "x"]) == {"scene-1/0004": 1, "x": 2}
    coco = coco_gt_to_dict({"scene/1": boxes([0, 0, 1, 1], ["car"])}, ["car"])
    assert coco["images"] == [{"id": 1, "file_name": "scene/1"}]
    assert coco["categories"] == [{"id": 1, "name": "car"}]
    assert coco["annotations"][0]["area"] == 1.0 and coco["annotations"][0]["id"] == 1


# --------------------------------------------------------------------------- malformed files

VALID_GT = {"images": [{"id": 1}, {"id": 2}],
            "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 4, 4], "area": 16,
                             "iscrowd": 0},
                            {"id": 2, "image_id": 2, "category_id": 2, "bbox": [1, 1, 2, 3]}],
            "categories": [{"id": 1, "name": "car"}, {"id": 2, "name": "person"}]}
VALID_DETS = [{"image_id": 1, "category_id": 1, "bbox": [0, 0, 4, 4], "score": 0.9},
              {"image_id": 2, "category_id": 2, "bbox": [1, 1, 2, 2], "score": 0.4}]


@pytest.mark.parametrize("edit, field", [
    (lambda d: d.pop("annotations"), "'annotations'"),
    (lambda d: d["annotations"][1]["bbox"].pop(), r"annotations\[1\].bbox"),
    (lambda d: d["annotations"][0].__setitem__("bbox", [0, 0, -1, 4]), r"annotations\[0\].bbox"),
    (lambda d: d["annotations"][0].__setitem__("category_id", 99), r"annotations\[0\].category_id"),
    (lambda d: d["annotations"][1].__setitem__("image_id", "2"), r"annotations\[1\].image_id"),
    (lambda d: d["annotations"][0].__setitem__("area", "16"), r"annotations\[0\].area"),
    (lambda d: d["annotations"][0].__setitem__("iscrowd", 2), r"annotations\[0\].iscrowd"),
    (lambda d: d["categories"][1].__setitem__("name", "car"), r"categories\[1\]"),
    (lambda d: d["images"].append({"id": 1}), "duplicate image ids"),
])
def test_malformed_ground_truth_names_file_and_field(tmp_path, edit, field):
    data = copy.deepcopy(VALID_GT)
    edit(data)
    path = tmp_path / "gt.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=field) as info:
        load_coco_gt(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("edit, field", [
    (lambda d: d[0].pop("score"), r"\[0\]: missing field 'score'"),
    (lambda d: d[1].__setitem__("score", float("nan")), r"\[1\].score"),
    (lambda d: d[1].__setitem__("image_id", 5), r"\[1\].image_id"),
    (lambda d: d[0].__setitem__("category_id", 7), r"\[0\].category_id"),
    (lambda d: d.append([0, 0, 1, 1]), r"\[2\]: expected an object"),
])
def test_malformed_detections_name_file_and_field(tmp_path, edit, field):
    gt = coco_gt_from_dict(VALID_GT)
    data = copy.deepcopy(VALID_DETS)
    edit(data)
    path = tmp_path / "dets.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=field) as info:
        load_coco_dets(path, gt)
    assert str(path) in str(info.value)


def test_unreadable_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: not valid JSON"):
        load_coco_gt(bad)
    bad.write_text("[1, 2]")
    with pytest.raises(ValueError, match="bad.json: expected a COCO object"):
        load_coco_gt(bad)
    with pytest.raises(FileNotFoundError, match="missing.json"):
        load_coco_gt(tmp_path / "missing.json")


# --------------------------------------------------------------------------- fuzzing

EDGES = st.sampled_from([10**400, -(10**400), float("nan"), float("inf"), True, False, "", 0, -1, 1e308, [], {}])
LEAVES = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=4) | EDGES
VALUES = (st.recursive(LEAVES, lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=4), c, max_size=3),
                       max_leaves=6)
          | st.lists(LEAVES, min_size=4, max_size=4))   # often a bbox of the right length, one bad entry


def paths(node, prefix=()):
    yield prefix
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, child in items:
        yield from paths(child, prefix + (key,))


def mutated(base, path, value, delete):
    data = copy.deepcopy(base)
    if not path:
        return value
    parent = data
    for key in path[:-1]:
        parent = parent[key]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return data


FUZZ = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(st.sampled_from(list(paths(VALID_GT))), VALUES, st.booleans())
def test_fuzzed_ground_truth_reads_or_raises_value_error(path, value, delete):
    data = mutated(VALID_GT, path, value, delete and bool(path))
    try:
        gt = coco_gt_from_dict(data, "fuzz.json")
    except ValueError as e:
        assert "fuzz.json" in str(e)
        return
    again = coco_gt_from_dict(gt.to_dict())      # whatever reads, writes and reads back the same
    assert again.category_ids == gt.category_ids and again.image_ids == gt.image_ids
    dets = {sid: Boxes2D(b.xyxy, b.names, np.ones(len(b), np.float32)) for sid, b in gt.boxes.items()}
    m = coco_evaluate(gt, dets)
    assert np.isnan(m.map) or 0.0 <= m.map <= 1.0


@FUZZ
@given(st.sampled_from(list(paths(VALID_DETS))), VALUES, st.booleans())
def test_fuzzed_detections_read_or_raise_value_error(path, value, delete):
    gt = coco_gt_from_dict(VALID_GT)
    data = mutated(VALID_DETS, path, value, delete and bool(path))
    try:
        dets = coco_dets_from_list(data, gt.category_ids, gt.image_ids, "fuzz.json")
    except ValueError as e:
        assert "fuzz.json" in str(e)
        return
    assert set(dets) == set(gt.boxes)


@pytest.mark.parametrize("bbox", [[3.4028235677973366e+38, 0, 1, 1], [3e38, 0, 3e38, 1], [0, -3.5e38, 1, 1]])
def test_a_box_past_float32s_range_is_refused_by_name(bbox):
    """Found by the fuzz test: a bbox finite in float64 but not as the float32 corners the boxes
    are kept in would read, then write inf, which no reader takes back."""
    data = copy.deepcopy(VALID_GT)
    data["annotations"][0]["bbox"] = bbox
    with pytest.raises(ValueError, match=r"big\.json: annotations\[0\]\.bbox: expected corners"):
        coco_gt_from_dict(data, "big.json")

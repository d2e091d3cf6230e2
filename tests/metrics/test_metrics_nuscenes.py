"""The nuScenes AP against the official devkit's numbers and hand cases.

The fixture below (fixture_gt / fixture_pred) was run through nuscenes-devkit 1.2.0, config
detection_cvpr_2019; DEVKIT_* are the numbers it printed for class car."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dsfec_jax.data.points.frame import Boxes
from dsfec_jax.metrics import nuscenes as nm
from dsfec_jax.metrics import submission as sub

REPO = Path(__file__).resolve().parents[2]
# nuscenes-devkit 1.2.0 (detection_cvpr_2019) on the fixture, class car.
DEVKIT_CAR_AP = {0.5: 0.014198, 1.0: 0.255967, 2.0: 0.39670781893004115, 4.0: 0.707613}
DEVKIT_MAX_RECALL_2M = 0.75
DEVKIT_TRANS_ERR_2M = 0.5271580082617457


def box(tok, x, y, score=None, name="car", **extra):
    b = {"sample_token": tok, "translation": [x, y, 0.0], "size": [1.9, 4.5, 1.6],
         "rotation": sub.yaw_to_quaternion(0.0), "velocity": [0.0, 0.0], "detection_name": name,
         "attribute_name": "", **extra}
    if score is not None:
        b["detection_score"] = score
    return b


def fixture_gt():
    return {"s0": [box("s0", 10, 0), box("s0", 20, 5)],
            "s1": [box("s1", -5, 3), box("s1", 15, -10), box("s1", 0, 0, name="pedestrian")]}


def fixture_pred():
    return {"s0": [box("s0", 10.5, 0.3, 0.9), box("s0", 30, 30, 0.8), box("s0", 21.5, 5.0, 0.4)],
            "s1": [box("s1", -5, 6.0, 0.7), box("s1", 15.2, -10.1, 0.6)]}


def car_ap(gt, pred, th, **kw):
    return nm.evaluate(gt, pred, classes=("car",), dist_ths=(th,), **kw)["AP"]["car"][str(float(th))]


# ---- the devkit fixture -----------------------------------------------------------------------------------

@pytest.mark.parametrize("th", sorted(DEVKIT_CAR_AP))
def test_fixture_car_ap_matches_devkit(th):
    md = nm.accumulate(fixture_gt(), fixture_pred(), "car", th)
    assert nm.calc_ap(md, 0.1, 0.1) == pytest.approx(DEVKIT_CAR_AP[th], abs=1e-6)


def test_fixture_max_recall_and_trans_err_at_2m():
    md = nm.accumulate(fixture_gt(), fixture_pred(), "car", 2.0)
    assert md.max_recall == pytest.approx(DEVKIT_MAX_RECALL_2M, abs=1e-12)
    assert nm.calc_tp(md, 0.1, "trans_err") == pytest.approx(DEVKIT_TRANS_ERR_2M, abs=1e-12)
    assert nm.calc_ap(md, 0.1, 0.1) == pytest.approx(DEVKIT_CAR_AP[2.0], abs=1e-12)


def test_fixture_through_evaluate_gives_dsfec_numbers():
    out = nm.evaluate(fixture_gt(), fixture_pred())
    aps = [out["AP"]["car"][str(th)] for th in (0.5, 1.0, 2.0, 4.0)]
    assert aps == pytest.approx([DEVKIT_CAR_AP[th] for th in (0.5, 1.0, 2.0, 4.0)], abs=1e-6)
    assert out["AP@4"]["car"] == pytest.approx(DEVKIT_CAR_AP[4.0], abs=1e-6)
    assert out["class_mAP"]["car"] == pytest.approx(np.mean(aps))
    assert out["mAP"] == pytest.approx(np.mean(list(out["class_mAP"].values())))
    assert out["tp_errors"]["car"]["trans_err"] == pytest.approx(DEVKIT_TRANS_ERR_2M, abs=1e-12)
    assert out["num_gt"] == {"car": 4, "truck": 0, "pedestrian": 1, "bicycle": 0}


def test_project_boxes_give_the_same_numbers():
    gt = {t: sub.entries_to_boxes(v)[0] for t, v in fixture_gt().items()}
    pred = {t: sub.entries_to_boxes(v) for t, v in fixture_pred().items()}
    ref = nm.evaluate(fixture_gt(), fixture_pred())["AP"]["car"]
    assert nm.evaluate(gt, pred)["AP"]["car"] == pytest.approx(ref, abs=1e-6)  # float32 boxes, float32 scores


# ---- hand-checkable cases ---------------------------------------------------------------------------------

def test_perfect_predictions_give_ap_1():
    gt = {"a": [box("a", 5, 1), box("a", 12, -3)], "b": [box("b", 20, 4)]}
    pred = {t: [dict(b, detection_score=0.9 - 0.1 * i) for i, b in enumerate(v)] for t, v in gt.items()}
    for th in nm.DIST_THS:
        md = nm.accumulate(sub.validate_results(gt, is_gt=True), sub.validate_results(pred), "car", th)
        assert nm.calc_ap(md) == pytest.approx(1.0, abs=1e-12)  # same float arithmetic as the devkit: 1 + 4e-16
        assert md.max_recall == 1.0 and nm.calc_tp(md, 0.1, "trans_err") == 0.0


def test_no_predictions_give_ap_0():
    gt = {"a": [box("a", 5, 1)]}
    out = nm.evaluate(gt, {"a": []}, classes=("car",))
    assert out["AP"]["car"] == {"0.5": 0.0, "1.0": 0.0, "2.0": 0.0, "4.0": 0.0}
    assert out["tp_errors"]["car"]["trans_err"] == 1.0


def test_wrong_class_does_not_match():
    gt, pred = {"a": [box("a", 5, 1)]}, {"a": [box("a", 5, 1, 0.9, name="truck")]}
    out = nm.evaluate(gt, pred, classes=("car", "truck"))
    assert out["AP"]["car"]["4.0"] == 0.0 and out["AP"]["truck"]["4.0"] == 0.0


def test_score_order_matters():
    # One GT; a hit and a miss. Hit first: precision 1 up to recall 1, then 0.5 at recall 1 -> AP = 80.5/81.
    # Miss first: precision rises linearly 0 -> 0.5 over recall 0 -> 1 -> AP = 0.2.
    gt = {"a": [box("a", 5, 1)]}
    hit_first = {"a": [box("a", 5.1, 1, 0.9), box("a", 25, 1, 0.5)]}
    miss_first = {"a": [box("a", 5.1, 1, 0.5), box("a", 25, 1, 0.9)]}
    assert car_ap(gt, hit_first, 1.0) == pytest.approx(80.5 / 81, abs=1e-12)
    assert car_ap(gt, miss_first, 1.0) == pytest.approx(0.2, abs=1e-12)


def test_score_ties_go_to_the_later_prediction():
    # The devkit sorts (score, index) pairs and reverses them, so the later of two equal scores goes first.
    gt = {"a": [box("a", 5, 1)]}
    miss_listed_first = {"a": [box("a", 25, 1, 0.5), box("a", 5.1, 1, 0.5)]}
    assert car_ap(gt, miss_listed_first, 1.0) == pytest.approx(80.5 / 81, abs=1e-12)


def test_each_gt_is_matched_once():
    gt = {"a": [box("a", 5, 1)]}
    duplicates = {"a": [box("a", 5, 1, 0.9), box("a", 5, 1, 0.8)]}
    assert car_ap(gt, duplicates, 0.5) == pytest.approx(80.5 / 81, abs=1e-12)


def test_nearest_unmatched_gt_is_taken():
    # The first prediction takes the GT at x=11 (nearest); the second must fall back to x=10, 0.4 m away.
    gt = {"a": [box("a", 10, 0), box("a", 11, 0)]}
    pred = {"a": [box("a", 10.9, 0, 0.9), box("a", 10.4, 0, 0.8)]}
    assert car_ap(gt, pred, 0.5) == pytest.approx(1.0, abs=1e-12)


def test_distance_must_be_strictly_below_threshold():
    gt, pred = {"a": [box("a", 10, 0)]}, {"a": [box("a", 12, 0, 0.9)]}  # exactly 2 m apart
    assert car_ap(gt, pred, 2.0) == 0.0
    assert car_ap(gt, pred, 4.0) == pytest.approx(1.0, abs=1e-12)


def test_ground_plane_distance_ignores_z():
    gt, pred = {"a": [box("a", 10, 0)]}, {"a": [dict(box("a", 10, 0, 0.9), translation=[10.0, 0.0, 3.0])]}
    assert car_ap(gt, pred, 0.5) == pytest.approx(1.0, abs=1e-12)


# ---- the devkit's filters and checks ----------------------------------------------------------------------

def test_class_range_filters_far_boxes():
    gt, pred = {"a": [box("a", 45, 30)]}, {"a": [box("a", 45, 30, 0.9)]}  # 54 m > 50 m car range
    assert nm.evaluate(gt, pred, classes=("car",))["num_gt"]["car"] == 0
    out = nm.evaluate(gt, pred, classes=("car",), class_range=None)
    assert out["num_gt"]["car"] == 1 and out["AP"]["car"]["0.5"] == pytest.approx(1.0, abs=1e-12)
    near = {"a": [box("a", 45, 30, ego_translation=[20.0, 0.0, 0.0])]}  # ego distance given explicitly
    assert nm.evaluate(near, pred, classes=("car",))["num_gt"]["car"] == 1


def test_gt_without_points_is_dropped_by_default():
    gt = {"a": [box("a", 5, 1, num_pts=0), box("a", 9, 1, num_pts=3)]}
    assert nm.evaluate(gt, {"a": []}, classes=("car",))["num_gt"]["car"] == 1
    assert nm.evaluate(gt, {"a": []}, classes=("car",), drop_empty_gt=False)["num_gt"]["car"] == 2


def test_too_many_boxes_and_sample_mismatch_raise():
    gt = {"a": [box("a", 5, 1)]}
    with pytest.raises(ValueError, match="at most 500"):
        nm.evaluate(gt, {"a": [box("a", 5, 1, 0.5)] * 501})
    with pytest.raises(ValueError, match="cover exactly"):
        nm.evaluate(gt, {"b": []})


# ---- submission format ------------------------------------------------------------------------------------

def test_boxes_entries_round_trip():
    f32 = lambda x: np.array(x, np.float32)  # noqa: E731
    boxes = Boxes(f32([[1, 2, 0.5], [3, -4, 1]]), f32([[1.9, 4.5, 1.6], [0.6, 0.8, 1.7]]), f32([0.3, -2.9]),
                  f32([[1, 0], [0, -1]]), np.array(["car", "pedestrian"]))
    entries = sub.boxes_to_entries("tok", boxes, scores=np.array([0.8, 0.3]))
    assert entries[0]["rotation"] == pytest.approx([np.cos(0.15), 0, 0, np.sin(0.15)])
    back, scores = sub.entries_to_boxes(entries)
    for f in ("center", "size", "yaw", "velocity"):
        np.testing.assert_allclose(getattr(back, f), getattr(boxes, f), atol=1e-6)
    assert list(back.names) == ["car", "pedestrian"] and scores == pytest.approx([0.8, 0.3])


def test_submission_json_round_trip(tmp_path):
    path = tmp_path / "pred.json"
    pred = sub.validate_results(fixture_pred())
    sub.write_submission(path, pred)
    results, meta = sub.read_submission(path)
    assert results == pred
    assert meta == {"use_camera": False, "use_lidar": False, "use_radar": True, "use_map": False, "use_external": False}
    gt_path = tmp_path / "gt.json"
    sub.write_submission(gt_path, fixture_gt(), is_gt=True)
    gt, _ = sub.read_submission(gt_path, is_gt=True)
    assert gt["s1"][2]["detection_name"] == "pedestrian" and gt["s1"][2]["detection_score"] == -1.0


@pytest.mark.parametrize("field,value", [("translation", [1.0, 2.0]), ("size", [0.0, 4.5, 1.6]), ("rotation", "q"),
                                         ("velocity", ["fast", 0.0]), ("detection_name", "spaceship"),
                                         ("detection_score", None), ("attribute_name", "vehicle.flying"),
                                         ("sample_token", "s9"), ("num_pts", 2.5)])
def test_malformed_box_names_file_sample_and_field(tmp_path, field, value):
    bad = box("s1", 1, 2, 0.5)
    bad[field] = value
    if value is None:
        del bad[field]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"meta": {"use_radar": True}, "results": {"s0": [box("s0", 1, 2, 0.5)], "s1": [bad]}}))
    with pytest.raises(ValueError) as err:
        sub.read_submission(path)
    msg = str(err.value)
    assert str(path) in msg and "'s1'" in msg and f"'{field}'" in msg


@pytest.mark.parametrize("text,field", [('{"meta": {}}', "results"), ('{"results": {}}', "meta"),
                                        ('{"meta": {"use_radar": "yes"}, "results": {}}', "meta.use_radar"),
                                        ("{not json", "not valid JSON")])
def test_malformed_file_names_field(tmp_path, text, field):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(str(path))) as err:
        sub.read_submission(path)
    assert field in str(err.value)


def test_cli_prints_the_devkit_numbers(tmp_path):
    gt, pred = tmp_path / "gt.json", tmp_path / "pred.json"
    sub.write_submission(gt, fixture_gt(), is_gt=True)
    sub.write_submission(pred, fixture_pred())
    cmd = [sys.executable, "-m", "dsfec_jax.metrics.nuscenes", "--gt", str(gt), "--pred", str(pred), "--classes", "car"]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # in particular no "found in sys.modules" warning from the package __init__
    out = json.loads(proc.stdout)
    assert out["classes"] == ["car"] and out["dist_ths"] == [0.5, 1.0, 2.0, 4.0]
    assert [out["AP"]["car"][k] for k in ("0.5", "1.0", "2.0", "4.0")] == pytest.approx(
        [DEVKIT_CAR_AP[th] for th in (0.5, 1.0, 2.0, 4.0)], abs=1e-6)
    assert out["AP@4"]["car"] == pytest.approx(DEVKIT_CAR_AP[4.0], abs=1e-6)
    assert out["mAP"] == out["class_mAP"]["car"] == pytest.approx(np.mean(list(DEVKIT_CAR_AP.values())), abs=1e-6)

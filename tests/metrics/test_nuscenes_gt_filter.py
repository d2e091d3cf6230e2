"""The devkit's num_pts == 0 ground-truth filter, end to end: nuScenes tables -> Frame -> score / JSON.

nuscenes-devkit's load_gt sets num_pts = num_lidar_pts + num_radar_pts of each sample_annotation and
filter_eval_boxes drops ground truth with num_pts == 0 (nothing could see it). Synthetic frames have
no lidar and carry no counts: every box is kept (see evaluate.score).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from builders import build_tiny_nuscenes  # the hand-checked nuScenes table fixture

from dsfec_jax.data.points import nuscenes as nu
from dsfec_jax.data.points.frame import Boxes, Frame
from dsfec_jax.data.points.sources import to_dsfec_frame
from dsfec_jax.modalities.points.evaluate import score
from dsfec_jax.metrics import nuscenes as nm
from dsfec_jax.metrics import submission as sub
from dsfec_jax.modalities.points.predict import Detections

F32 = np.float32


def set_counts(root, counts: dict) -> None:
    """Give annotations num_lidar_pts / num_radar_pts: {token: (lidar, radar)}."""
    path = root / "v1.0-mini" / "sample_annotation.json"
    records = json.loads(path.read_text())
    for r in records:
        if r["token"] in counts:
            r["num_lidar_pts"], r["num_radar_pts"] = counts[r["token"]]
    path.write_text(json.dumps(records))


@pytest.fixture
def counted(tmp_path):
    """s1 holds a car nothing saw (0 + 0) and a pedestrian only the radar saw (0 + 2)."""
    root = build_tiny_nuscenes(tmp_path / "nuscenes")
    set_counts(root, {"a0": (9, 1), "a1": (0, 0), "a2": (4, 0), "p1": (0, 2), "d1": (7, 0)})
    return root


def pedestrian_detection() -> Detections:
    boxes = Boxes(np.array([[1, 0, 0.9]], F32), np.array([[0.6, 0.7, 1.8]], F32), np.array([-np.pi / 2], F32),
                  np.zeros((1, 2), F32), np.array(["pedestrian"]))
    return Detections(boxes, np.array([0.9], F32))


def test_reader_carries_lidar_plus_radar_counts(counted):
    boxes = nu.read_nuscenes_frame(counted, "s1").boxes
    assert list(boxes.names) == ["car", "pedestrian"]
    assert boxes.num_pts.tolist() == [0, 2]  # the devkit's sum: radar alone keeps the pedestrian
    mapped = to_dsfec_frame(nu.read_nuscenes_frame(counted, "s1"))  # what `dsfec eval --data nuscenes:` scores
    assert mapped.boxes.num_pts.tolist() == [0, 2]
    assert boxes.select(np.array([False, True])).num_pts.tolist() == [2]


def test_tables_without_counts_give_unknown_counts(tmp_path):
    boxes = nu.read_nuscenes_frame(build_tiny_nuscenes(tmp_path / "nu"), "s1").boxes
    assert boxes.num_pts.tolist() == [-1, -1]  # unknown: kept, as a prediction's -1 is


@pytest.mark.parametrize("value", [-1, 2.5, "3", True, None, [1]])
def test_bad_counts_name_the_file_record_and_field(tmp_path, value):
    root = build_tiny_nuscenes(tmp_path / "nu")
    set_counts(root, {"a1": (value, 0)})
    with pytest.raises(ValueError) as err:
        nu.read_nuscenes_frame(root, "s1")
    msg = str(err.value)
    assert "sample_annotation.json" in msg and "'a1'" in msg and "num_lidar_pts" in msg


def test_score_drops_ground_truth_nothing_saw(counted):
    frame = to_dsfec_frame(nu.read_nuscenes_frame(counted, "s1"))
    out = score([frame], {"s1": pedestrian_detection()}, classes=("car", "pedestrian"), match_classes=("car",))
    assert out["num_gt"] == {"car": 0, "pedestrian": 1}  # the unseen car is not a miss
    assert out["AP"]["pedestrian"]["4.0"] == pytest.approx(1.0)
    assert out["match_tables"]["car"].npos.sum() == 0  # bootstrap tables filter alike


def test_synthetic_frames_keep_every_box():
    """No lidar in a synthetic frame: every annotated box counts, even one no radar point hit."""
    car = Boxes(np.array([[10, 0, 0.8]], F32), np.array([[1.9, 4.5, 1.6]], F32), np.zeros(1, F32),
                np.zeros((1, 2), F32), np.array(["car"]))
    assert car.num_pts is None
    frame = Frame(np.zeros((0, 7), F32), ("x", "y", "z", "rcs", "vx_comp", "vy_comp", "dt"), car, "f0", "synthetic")
    empty = Detections(Boxes.empty(), np.zeros(0, F32))
    assert score([frame], {"f0": empty}, classes=("car",))["num_gt"]["car"] == 1


def test_submission_json_carries_counts(counted, tmp_path):
    boxes = nu.read_nuscenes_frame(counted, "s1").boxes
    entries = sub.boxes_to_entries("s1", boxes)  # as `dsfec predict --gt-out` writes ground truth
    assert [e["num_pts"] for e in entries] == [0, 2]
    path = tmp_path / "gt.json"
    sub.write_submission(path, {"s1": entries}, is_gt=True)
    gt, _ = sub.read_submission(path, is_gt=True)
    assert sub.entries_to_boxes(gt["s1"])[0].num_pts.tolist() == [0, 2]
    pred = {"s1": sub.boxes_to_entries("s1", *pedestrian_detection())}
    assert nm.evaluate(gt, pred, classes=("car", "pedestrian"))["num_gt"] == {"car": 0, "pedestrian": 1}
    assert all(e["num_pts"] == -1 for e in pred["s1"])  # predictions are never filtered by it


def test_boxes_check_the_count_shape():
    with pytest.raises(ValueError, match="num_pts"):
        Boxes(np.zeros((1, 3), F32), np.ones((1, 3), F32), np.zeros(1, F32), np.zeros((1, 2), F32),
              np.array(["car"]), num_pts=np.array([1, 2]))


def test_scoring_zero_frames_is_an_error():
    with pytest.raises(ValueError, match="no samples"):
        nm.evaluate({}, {})
    with pytest.raises(ValueError, match="no frames"):
        score([], {})

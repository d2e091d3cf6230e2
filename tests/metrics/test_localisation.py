"""metrics.localisation: greedy same-class IoU matching and the horizontal error by range bin."""

import math

import numpy as np
import pytest

from dsfec_jax.metrics.localisation import (format_localisation_table, horizontal_errors, localisation_table,
                                            match_frame)

GT = np.array([[0, 0, 10, 10], [20, 0, 30, 10], [40, 0, 50, 10]], np.float64)
GT_NAMES = ["car", "car", "pedestrian"]


def test_greedy_matching_by_score_same_class_and_iou_at_least_half():
    det = np.array([[0, 0, 10, 10],      # car, exact on gt 0
                    [1, 0, 11, 10],      # car, IoU 0.82 with gt 0, lower score: gt 0 is taken, nothing else
                    [20, 0, 30, 5],      # car, IoU exactly 0.5 with gt 1: matched (>=)
                    [40, 0, 50, 10],     # car on the pedestrian: wrong class
                    [41, 0, 51, 10]],    # pedestrian, IoU 0.82 with gt 2
                   np.float64)
    pairs = match_frame(GT, GT_NAMES, det, ["car", "car", "car", "car", "pedestrian"], [0.5, 0.9, 0.4, 0.8, 0.3])
    assert sorted(map(tuple, pairs.tolist())) == [(1, 0), (2, 1), (4, 2)]
    assert pairs[0].tolist() == [1, 0]                                  # the highest score goes first
    assert match_frame(GT, GT_NAMES, det[2:3] + [0, 0, 0, -0.1], ["car"], [1.0]).shape == (0, 2)   # IoU < 0.5
    assert match_frame(np.zeros((0, 4)), [], det, ["car"] * 5, np.ones(5)).shape == (0, 2)
    with pytest.raises(ValueError, match="one name"):
        match_frame(GT, GT_NAMES[:2], det, ["car"] * 5, np.ones(5))


def test_errors_by_range_bin():
    pred = np.array([[3.0, 4.0, 9.0], [0.0, 1.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    true = np.zeros((4, 3))
    e = horizontal_errors(pred, true)
    np.testing.assert_allclose(e, [5.0, 1.0, 10.0, 0.0])                # the height difference is ignored
    rows = {r.range_m: r for r in localisation_table(e, [5.0, 15.0, 15.0, 50.0])}
    assert rows["0-10"].count == 1 and rows["0-10"].mean_m == 5.0
    assert rows["10-20"].median_m == pytest.approx(5.5) and rows["10-20"].p90_m == pytest.approx(9.1)
    assert rows["20-40"].count == 0 and math.isnan(rows["20-40"].mean_m)
    assert rows["0-40"].count == 3 and rows["all"].count == 4
    assert "| 40+ | 1 | 0.00 | 0.00 | 0.00 |" in format_localisation_table(list(rows.values()))
    with pytest.raises(ValueError, match="matched"):
        horizontal_errors(pred[:2], true)
    with pytest.raises(ValueError, match="one finite error"):
        localisation_table([np.nan], [5.0])

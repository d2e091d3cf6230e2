"""Dense depth metrics (Eigen / monodepth compute_errors) against hand-computed values."""

import math

import numpy as np
import pytest

from dsfec_jax.metrics.depth.dense import METRICS, compute_errors, depth_errors, mean_errors, valid_mask


def test_hand_case():
    gt = np.array([1.0, 1.0, 1.0, 1.0])
    pred = np.array([1.0, 1.5, 1.9, 3.0])  # ratios 1, 1.5, 1.9, 3 against 1.25, 1.5625, 1.953
    e = compute_errors(gt, pred)
    assert e["abs_rel"] == pytest.approx((0 + 0.5 + 0.9 + 2.0) / 4)
    assert e["sq_rel"] == pytest.approx((0 + 0.25 + 0.81 + 4.0) / 4)
    assert e["rmse"] == pytest.approx(math.sqrt((0 + 0.25 + 0.81 + 4.0) / 4))
    assert e["rmse_log"] == pytest.approx(math.sqrt((math.log(1.5) ** 2 + math.log(1.9) ** 2 + math.log(3) ** 2) / 4))
    assert (e["a1"], e["a2"], e["a3"]) == (0.25, 0.5, 0.75)


def test_ratio_is_symmetric():
    """max(gt / pred, pred / gt): under- and over-estimates by the same factor count alike."""
    assert compute_errors(np.array([2.0]), np.array([1.0]))["a3"] == compute_errors(np.array([1.0]), np.array([2.0]))["a3"]


def test_invalid_ground_truth_is_left_out_and_prediction_capped():
    gt = np.array([[2.0, np.inf, 100.0, 0.0], [4.0, np.nan, 5.0, 1e-4]])
    pred = np.array([[2.0, 7.0, 7.0, 7.0], [np.inf, 3.0, 500.0, 7.0]])
    assert valid_mask(gt).tolist() == [[True, False, False, False], [True, False, True, False]]
    e = depth_errors(gt, pred)
    # scored: (2, 2), (4, inf -> 80), (5, 500 -> 80)
    assert e["pixels"] == 3
    assert e["abs_rel"] == pytest.approx((0 + 76 / 4 + 75 / 5) / 3)
    assert e["a1"] == pytest.approx(1 / 3)


def test_custom_cap():
    gt, pred = np.array([10.0, 30.0, 60.0]), np.array([10.0, 60.0, 60.0])
    assert depth_errors(gt, pred, max_depth=40.0)["pixels"] == 2
    assert depth_errors(gt, pred, max_depth=40.0)["abs_rel"] == pytest.approx((0 + 10 / 30) / 2)  # pred capped at 40


def test_mean_is_per_image_not_pooled():
    small = depth_errors(np.array([1.0]), np.array([2.0]))          # abs_rel 1
    large = depth_errors(np.full(9, 1.0), np.full(9, 1.0))          # abs_rel 0
    m = mean_errors([small, large])
    assert m["abs_rel"] == pytest.approx(0.5)  # pooled over pixels it would be 0.1
    assert m["images"] == 2 and m["pixels"] == 10 and set(METRICS) <= set(m)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="shape"):
        depth_errors(np.ones((2, 2)), np.ones((2, 3)))
    with pytest.raises(ValueError, match="no ground-truth pixel"):
        depth_errors(np.full((2, 2), np.inf), np.ones((2, 2)))
    with pytest.raises(ValueError, match="no images"):
        mean_errors([])

"""metrics.depth.per_detection: the per-detection depth error table by range bin."""

import math

import numpy as np
import pytest

from dsfec_jax.metrics.depth.per_detection import RANGE_BINS_M, depth_error_table, format_depth_table, range_rows


def test_rows_by_range_bin_with_hand_numbers():
    true = np.array([5.0, 8.0, 15.0, 30.0, 30.0, 60.0])
    pred = np.array([5.2, 8.0, 13.5, 31.0, np.nan, 66.0])   # 4 %, 0 %, 10 %, 3.33 %, no estimate, 10 %
    rows = {r.range_m: r for r in depth_error_table(pred, true)}
    assert list(rows) == ["0-10", "10-20", "20-40", "40+", "0-40", "all"]
    near = rows["0-10"]
    assert (near.count, near.invalid) == (2, 0)
    assert near.mean_rel_pct == pytest.approx(2.0) and near.median_rel_pct == pytest.approx(2.0)
    assert near.rmse_m == pytest.approx(math.sqrt(0.2 ** 2 / 2)) and near.within_5pct == 100.0
    mid = rows["20-40"]
    assert (mid.count, mid.invalid) == (2, 1) and mid.mean_rel_pct == pytest.approx(100 / 30)
    assert rows["10-20"].within_5pct == 0.0 and rows["40+"].rmse_m == pytest.approx(6.0)
    claim = rows["0-40"]
    assert (claim.count, claim.invalid) == (5, 1) and claim.within_5pct == pytest.approx(75.0)
    assert rows["all"].count == 6 and rows["all"].mean_rel_pct == pytest.approx((4 + 0 + 10 + 10 / 3 + 10) / 5)


def test_edges_belong_to_the_upper_bin_and_empty_bins_are_nan():
    rows = {r.range_m: r for r in depth_error_table([10.0, 20.0], [10.0, 20.0])}
    assert rows["0-10"].count == 0 and math.isnan(rows["0-10"].mean_rel_pct)
    assert rows["10-20"].count == 1 and rows["20-40"].count == 1
    assert [label for label, _ in range_rows([1.0], (0, 5, math.inf))] == ["0-5", "5+", "0-40", "all"]
    assert RANGE_BINS_M == (0.0, 10.0, 20.0, 40.0, math.inf)


def test_bad_inputs_are_refused_and_the_table_prints():
    with pytest.raises(ValueError, match="one each per detection"):
        depth_error_table([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="finite and > 0"):
        depth_error_table([1.0], [np.inf])
    text = format_depth_table(depth_error_table([5.1, 25.0], [5.0, 24.0]))
    assert "| 0-40 (paper: < 5 % error) | 2 | 0 |" in text and text.count("\n") == 8

"""The AP of resampled evaluation sets (bootstrap) against nuscenes.evaluate on the same multisets."""

import numpy as np
import pytest

from dsfec_jax.metrics import nuscenes as nm
from dsfec_jax.metrics import resampling as rs
from builders import box, random_scene


def evaluate_ap(gt, pred):
    result = nm.evaluate(gt, pred, classes=("car",), drop_empty_gt=False)
    return np.array([result["AP"]["car"][str(th)] for th in nm.DIST_THS])


def multiset(boxes, counts, samples):
    """The samples repeated counts[s] times under fresh tokens (what a bootstrap resample means)."""
    out = {}
    for s, tok in enumerate(samples):
        for k in range(counts[s]):
            out[f"{tok}#{k}"] = [{**b, "sample_token": f"{tok}#{k}"} for b in boxes[tok]]
    return out


def test_every_sample_once_is_the_devkit_ap():
    gt, pred = random_scene()
    table = rs.match_table(gt, pred, "car", drop_empty_gt=False)
    expected = evaluate_ap(gt, pred)
    assert len(set(np.round(expected, 6))) > 1, "the fixture should separate the thresholds"
    np.testing.assert_array_equal(rs.resampled_ap(table), expected)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_resample_equals_evaluating_the_repeated_samples(seed):
    gt, pred = random_scene(seed=seed)
    table = rs.match_table(gt, pred, "car", drop_empty_gt=False)
    counts = rs.bootstrap_counts(len(table.samples), 1, seed)[0]
    assert counts.max() > 1 and (counts == 0).any()
    expected = evaluate_ap(multiset(gt, counts, table.samples), multiset(pred, counts, table.samples))
    np.testing.assert_allclose(rs.resampled_ap(table, counts), expected, atol=1e-12)


def test_round_trip_and_bad_bytes():
    gt, pred = random_scene()
    table = rs.match_table(gt, pred, "car", drop_empty_gt=False)
    back = rs.MatchTable.from_bytes(table.to_bytes())
    assert back.samples == table.samples and back.thresholds == table.thresholds and back.kind == "nuscenes"
    np.testing.assert_array_equal(rs.resampled_ap(back), rs.resampled_ap(table))
    with pytest.raises(ValueError, match="x.npz: not a match table"):
        rs.MatchTable.from_bytes(b"garbage", "x.npz")


def test_no_ground_truth_or_no_hits_give_zero():
    gt = {"a": [], "b": [box("b", 0, 0)]}
    pred = {"a": [box("a", 5, 5, 0.9)], "b": [box("b", 40, 0, 0.5)]}
    table = rs.match_table(gt, pred, "car", drop_empty_gt=False)
    assert rs.resampled_ap(table).tolist() == [0.0] * 4
    assert rs.resampled_ap(table, np.array([2, 0])).tolist() == [0.0] * 4
    with pytest.raises(ValueError, match="2 samples"):
        rs.resampled_ap(table, np.array([1, 1, 1]))

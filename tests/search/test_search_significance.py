"""The paired bootstrap under a search table: intervals, rank stability, refusals."""

import numpy as np
import pytest

from dsfec_jax.metrics import resampling as rs
from search import report, significance
from builders import box, random_scene


def record(label, gt, pred, seed=0, status="ok"):
    table = rs.match_table(gt, pred, "car", drop_empty_gt=False)
    car_map = 100 * float(rs.resampled_ap(table).mean())
    return {"key": f"{label}-{seed}", "base": "dsfec_l", "label": label, "seed": seed, "status": status,
            "metrics": {"car_mAP": car_map, "car_AP4": 0.0, "mAP": 0.0},
            "costs": {"params": 1e6, "gflops": 1.0, "memory_mb": 1.0, "latency_ms": 1.0},
            "matches": {"car": table.to_text()}}


def perfect(gt):
    return {tok: [{**b, "detection_score": 0.9} for b in boxes] for tok, boxes in gt.items()}


def test_a_clearly_better_candidate_is_resolved_and_a_copy_is_not():
    gt, noisy = random_scene(n_samples=40, seed=5)
    records = [record("noisy", gt, noisy), record("copy", gt, noisy), record("perfect", gt, perfect(gt))]
    sig = significance.paired_bootstrap(records, "noisy", resamples=200)
    assert sig["point"]["perfect"] == pytest.approx(100.0) and sig["best"] == "perfect"
    assert sig["delta"]["copy"]["ci95"] == [0.0, 0.0] and sig["delta"]["copy"]["p_better"] == 0.0
    assert sig["delta"]["perfect"]["ci95"][0] > 5 and sig["delta"]["perfect"]["p_better"] == 1.0
    assert sig["p_best_stays_best"] == 1.0 and sig["sd"]["noisy"] > 0
    assert "Differences from the base whose 95 % interval excludes 0: perfect." in significance.summary(sig)


def test_point_values_are_the_records_and_seeds_are_averaged():
    gt, a = random_scene(n_samples=20, seed=1)
    _, b = random_scene(n_samples=20, seed=1)
    b = {tok: [{**x, "detection_score": 1 - x["detection_score"]} for x in boxes] for tok, boxes in b.items()}
    recs = [record("x", gt, a, 0), record("x", gt, b, 1), record("y", gt, perfect(gt))]
    sig = significance.paired_bootstrap(recs, "y", resamples=50)
    assert sig["point"]["x"] == pytest.approx(np.mean([r["metrics"]["car_mAP"] for r in recs[:2]]), abs=1e-4)


def test_seeds_that_disagree_widen_the_interval():
    """Seed 0 says a >> b, seed 1 says b >> a: the seed-averaged difference is exactly 0 on every frame
    draw, so only resampling the seeds shows how unsure the order is."""
    gt, noisy = random_scene(n_samples=30, seed=4)
    recs = [record("a", gt, perfect(gt), 0), record("a", gt, noisy, 1),
            record("b", gt, noisy, 0), record("b", gt, perfect(gt), 1)]
    sig = significance.paired_bootstrap(recs, "b", resamples=200)
    assert sig["seeds"] == 2 and sig["delta"]["a"]["point"] == pytest.approx(0.0, abs=1e-9)
    low, high = sig["delta"]["a"]["ci95"]
    assert low < -5 and high > 5
    assert "over the 30 validation frames and the 2 seeds" in significance.summary(sig)


def test_records_without_tables_or_on_other_frames():
    gt, pred = random_scene(n_samples=6)
    recs = [record("a", gt, pred), record("b", gt, pred)]
    assert significance.paired_bootstrap([{**recs[0], "matches": {}}, recs[1]], "a") is None
    other = {"z": [box("z", 0, 0)]}
    with pytest.raises(ValueError, match="other validation frames"):
        significance.paired_bootstrap([recs[0], record("c", other, perfect(other))], "a")


def test_report_prints_the_interval_column(tmp_path):
    from search.journal import Journal

    gt, noisy = random_scene(n_samples=30, seed=2)
    for r in (record("base", gt, noisy), record("better", gt, perfect(gt))):
        Journal(tmp_path).append(r)
    (tmp_path / "search.json").write_text('{"base_label": "base", "title": "t"}')
    out = report.write_reports(tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "Δ Car mAP 95 % CI (frames)" in md and "significance.json" in out["files"]
    assert "Evaluation noise (paired bootstrap over the 30 validation frames" in md
    assert "matches" not in (tmp_path / "records.json").read_text()
    other = {"z": [box("z", 0, 0)]}
    Journal(tmp_path).append(record("elsewhere", other, perfect(other)))
    out = report.write_reports(tmp_path)  # the tables are still written, with the reason
    assert out["significance"] is None and not (tmp_path / "significance.json").exists()
    assert "No bootstrap intervals: candidate 'elsewhere' was scored on other validation frames" in \
        (tmp_path / "report.md").read_text()


def test_report_names_classes_that_score_zero_in_every_candidate(tmp_path):
    """'mAP (4 classes)' averages in classes no candidate detects: the report says which."""
    from search.journal import Journal

    gt, noisy = random_scene(n_samples=6, seed=3)
    for label, ped in (("a", 0.0), ("b", 0.02)):
        r = record(label, gt, noisy)
        r["metrics"]["class_mAP"] = {"car": 0.1, "truck": 0.2, "pedestrian": ped, "bicycle": 0.0}
        Journal(tmp_path).append(r)
    report.write_reports(tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "averages the class mAPs of car, truck, pedestrian, bicycle; bicycle scores 0.0 in every candidate" in md
    assert "pedestrian scores" not in md

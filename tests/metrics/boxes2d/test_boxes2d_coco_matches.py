"""COCO AP on resampled image sets (metrics.boxes2d.coco_matches) against pycocotools on the same multisets."""

from __future__ import annotations

import numpy as np
import pytest

from dsfec_jax.metrics import resampling as rs
from dsfec_jax.metrics.boxes2d.coco import coco_evaluate
from dsfec_jax.metrics.boxes2d.coco_matches import resampled_coco_ap
from builders import boxes2d_scene as scene

CLASSES = ("car", "person", "truck")  # boxes2d_scene's


def test_every_image_once_is_cocoevals_per_class_ap():
    gts, dets = scene()
    m = coco_evaluate(gts, dets, CLASSES, match_classes=CLASSES)
    assert set(m.match_tables) == set(CLASSES)
    checked = 0
    for name, table in m.match_tables.items():
        ap = resampled_coco_ap(table)
        standard = [i for i, t in enumerate(table.thresholds) if t >= 0.5 - 1e-9]
        if np.isnan(m.per_class_ap50[name]):
            assert np.isnan(ap).all()
            continue
        assert ap[standard[0]] == m.per_class_ap50[name]  # bit-equal: the same accumulate arithmetic
        assert np.mean(ap[standard]) == pytest.approx(m.per_class_ap[name], abs=1e-12)
        checked += 1
    assert checked == len(CLASSES)
    assert len({round(v, 6) for v in m.per_class_ap50.values()}) > 1, "the fixture should separate the classes"


def multiset(boxes, counts, samples):
    """The images repeated counts[s] times under fresh ids (what a bootstrap resample means)."""
    return {f"{s}#{k}": boxes[s] for i, s in enumerate(samples) for k in range(counts[i])}


@pytest.mark.parametrize("seed", [1, 2])
def test_a_resample_equals_pycocotools_on_the_repeated_images(seed):
    gts, dets = scene(seed=seed)
    tables = coco_evaluate(gts, dets, CLASSES, match_classes=CLASSES).match_tables
    samples = tables["car"].samples
    counts = rs.bootstrap_counts(len(samples), 1, seed)[0]
    assert counts.max() > 1 and (counts == 0).any()
    # fresh ids in draw order: pycocotools' image order (sorted ids) equals the table's repeat order
    expected = coco_evaluate(multiset(gts, counts, samples), multiset(dets, counts, samples), CLASSES)
    for name, table in tables.items():
        ap = rs.table_ap(table, counts)
        assert ap[list(table.thresholds).index(0.5)] == pytest.approx(expected.per_class_ap50[name], abs=1e-12)


def test_round_trip_kind_and_refusals():
    gts, dets = scene()
    table = coco_evaluate(gts, dets, CLASSES, match_classes=("car",)).match_tables["car"]
    back = rs.MatchTable.from_text(table.to_text())
    assert back.kind == "coco" and back.thresholds == table.thresholds
    np.testing.assert_array_equal(resampled_coco_ap(back), resampled_coco_ap(table))
    with pytest.raises(ValueError, match="nuScenes tables"):
        rs.resampled_ap(table)
    with pytest.raises(ValueError, match="24 images"):
        resampled_coco_ap(table, np.ones(3, int))
    with pytest.raises(ValueError, match=r"classes \['bus'\]"):
        coco_evaluate(gts, dets, CLASSES, match_classes=("bus",))


def test_a_draw_without_ground_truth_is_nan_and_only_asked_columns_are_computed():
    gts, dets = scene()
    table = coco_evaluate(gts, dets, CLASSES, match_classes=("truck",)).match_tables["truck"]
    no_truck = (table.npos == 0).astype(np.int64)
    assert np.isnan(resampled_coco_ap(table, no_truck)).all()
    only = resampled_coco_ap(table, None, [1])
    assert not np.isnan(only[1]) and np.isnan(np.delete(only, 1)).all()

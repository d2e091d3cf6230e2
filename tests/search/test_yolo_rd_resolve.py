"""experiments/yolo_rd_resolve.py: a table's rows re-scored on held-out maps, the noise of each
difference split into its evaluation (maps) and training (seeds) parts, and the seeds a gap needs
(records made up from synthetic boxes, the held-out scorer replaced: no training)."""

import math

import pytest

from dsfec_jax import zoo
from experiments import yolo_rd_resolve as resolve
from experiments import yolo_rd_tables as tables
from test_yolo_rd_tables import record


@pytest.fixture
def fake_held_out(monkeypatch):
    """The held-out scorer answers with the record's own figures and tables (what its weights scored)."""
    monkeypatch.setattr(resolve, "held_out", lambda r, run_dir, split, count: {
        "metrics": r["metrics"], "matches": r["matches"]})


def test_noise_parts_and_the_seeds_a_gap_needs():
    assert resolve.pooled_seed_sd([[1.0, 3.0], [5.0, 5.0], [2.0]]) == (1.0, 2)  # variances 2 and 0, 2 dof
    assert resolve.pooled_seed_sd([[1.0], [2.0]]) == (None, 0)
    assert resolve.resolvable(1.0, 0.0, 5) == pytest.approx(resolve.Z95)
    assert resolve.resolvable(0.0, 1.0, 2) == pytest.approx(resolve.Z95)  # 2 sd_seed^2 / 2 seeds
    assert resolve.seeds_needed(1.0, 1.0, 1.0) is None  # the maps' noise alone hides a 1-point gap
    n = resolve.seeds_needed(3.0, 0.5, 2.0)
    assert resolve.resolvable(0.5, 2.0, n) < 3.0 <= resolve.resolvable(0.5, 2.0, n - 1)


def test_a_table_resolves_what_its_seeds_and_maps_separate(fake_held_out, tmp_path):
    fusion2 = tables.row_overrides(tables.fusion_variant(2))
    fusion3 = tables.row_overrides(tables.fusion_variant(3))
    adapter = tables.row_overrides(zoo.config("yolov8n_adapter"))
    records = [record(fusion2, s, 3.0) for s in (0, 1)] + [record(fusion3, s, 3.0) for s in (0, 1)] + \
        [record(adapter, s, 0.2) for s in (0, 1)]
    out = resolve.resolve("table6", records, tmp_path, 24, tables.EARLIER_SMALL_SIDE, 200)
    rows = {row["label"]: row for row in out["rows"]}
    assert list(rows) == [label for label, _, _ in tables.table_rows("table6")]
    sharp = rows["yolov8n_adapter"]
    assert sharp["ci95"][0] > 0 and sharp["delta"] > 10  # far sharper boxes: above noise
    copy = rows["yolov8n_adapter fusion=3"]  # the same boxes as the first row: no difference at all
    assert copy["delta"] == 0 and copy["ci95"] == [0.0, 0.0] and copy["sd_maps"] == 0
    assert out["sd_seed"] > 0 and out["sd_seed_dof"] == 3
    values = resolve.seed_values(resolve.held_out_records("table6", records, tmp_path, 24, tables.EARLIER_SMALL_SIDE),
                                 tables.STATISTICS["mAP50_95"])
    assert values[2] == pytest.approx([r["metrics"]["mAP50_95"] for r in records[4:]])  # the trial's own figure
    assert math.isclose(sharp["paper_gap"], 45.1 - 42.7)
    text = resolve.markdown(out)
    assert "above noise (paper +2.4)" in text and "within noise (paper +0.9)" in text and "pooled over the rows" in text


def test_a_table_without_two_finished_rows_is_refused(fake_held_out, tmp_path):
    only = [record(tables.row_overrides(tables.fusion_variant(2)), 0, 1.0)]
    with pytest.raises(SystemExit, match="1 row"):
        resolve.resolve("table6", only, tmp_path, 24, tables.EARLIER_SMALL_SIDE, 100)

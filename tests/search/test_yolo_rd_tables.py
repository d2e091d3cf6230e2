"""The YOLO-RD table layouts (experiments/yolo_rd_tables.py): rows are configs of one family written
as overrides of yolov8n, rows shared by tables map to one trial, and the printed table puts ours
beside the paper's with the seed noise verdict (records made up here: no training)."""

import pytest

from dsfec_jax import zoo
from experiments import yolo_rd_tables as tables


def test_every_row_is_a_valid_config_and_shared_rows_share_overrides():
    keys = {}
    for table in ("table3", "table4", "table5", "table6"):
        for label, cfg, _ in tables.table_rows(table):
            overrides = tables.overrides_of(cfg)
            assert tables.overrides_of(zoo.config("yolov8n", **overrides)) == overrides  # a valid config
            keys.setdefault(tables._row_key(overrides), set()).add(label)
    assert all(len(labels) == 1 for labels in keys.values()), keys  # one label per distinct network
    assert tables.overrides_of(zoo.config("yolov8n_adapter")) == {"adapter_input": "gray"}
    # 5 + 6 + 6 + 3 rows, of which 15 distinct networks (yolov8n and yolov8n_adapter recur)
    assert len(keys) == 15


def record(overrides, seed, map50_95, params=3.0e6):
    return {"status": "ok", "overrides": overrides, "seed": seed, "label": "x",
            "metrics": {"mAP50": map50_95 + 20, "mAP70": map50_95 + 5, "mAP50_95": map50_95},
            "costs": {"params": params}}


def test_markdown_gives_ours_beside_the_paper_and_the_noise_verdict():
    adapter = tables.overrides_of(zoo.config("yolov8n_adapter"))
    fusion2 = tables.overrides_of(tables.fusion_variant(2))
    records = [record(fusion2, 0, 10.0), record(fusion2, 1, 11.0), record(adapter, 0, 20.0), record(adapter, 1, 21.0)]
    text = tables.markdown("table6", records)
    lines = text.splitlines()
    assert lines[2].startswith("| yolov8n_adapter fusion=2 | 2 | 30.5 ± 0.7 (68.9)")
    assert "| yolov8n_adapter | 1 |" in text and "+10.0 (above noise)" in text
    assert "| - (67.8)" in lines[3]  # fusion 3: not run yet
    assert "2 x pooled seed sd of mAP50_95 = 1.41 points" in text


def test_unknown_table_is_refused():
    with pytest.raises(SystemExit, match="unknown table"):
        tables.table_rows("table9")

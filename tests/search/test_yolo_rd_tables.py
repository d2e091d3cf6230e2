"""The YOLO-RD table layouts (experiments/yolo_rd_tables.py): rows are configs of one family written
as overrides of yolov8n, rows shared by tables map to one trial, and the printed table puts ours
beside the paper's with the bootstrap noise verdict (records made up here from synthetic boxes: no
training)."""

import json

import pytest

from builders import BOXES2D_CLASSES, boxes2d_scene
from dsfec_jax import zoo
from dsfec_jax.metrics.boxes2d.coco import coco_evaluate
from experiments import yolo_rd_tables as tables
from search.significance import matches_entry


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


def test_every_row_trains_with_the_small_box_rule_the_readmes_tables_were_measured_with():
    """The family now defaults to ultralytics 8.4.190's rule (16, 16); the README's tables were
    measured with (8, 16), so the tables' trials pin it (or the rule --small-side names), and a
    record trained with the other rule fills no row."""
    for table in ("table3", "table4", "table5", "table6"):
        for _, cfg, _ in tables.table_rows(table):
            assert zoo.config("yolov8n", **tables.row_overrides(cfg)).assign_small_side == (8.0, 16.0)
            assert zoo.config("yolov8n", **tables.row_overrides(cfg, (16, 16))).assign_small_side == (16.0, 16.0)
    fusion2 = tables.fusion_variant(2)
    other_rule = [record(tables.row_overrides(fusion2, (16.0, 16.0)), 0, 1.0)]
    assert "| yolov8n_adapter fusion=2 | 2 | - (68.9)" in tables.markdown("table6", other_rule)
    assert "| yolov8n_adapter fusion=2 | 2 | - (68.9)" not in tables.markdown("table6", other_rule, (16.0, 16.0))


def record(overrides, seed, sloppiness, fake_map=None):
    """A trial record whose figures and match tables come from scoring a synthetic scene (the same
    24 frames for every row; `sloppiness` scales the box jitter, so larger is worse; another seed
    jitters a little more, as another training run would score a little differently)."""
    gts, dets = boxes2d_scene(seed=0, sloppiness=sloppiness * (1 + 0.2 * seed))
    m = coco_evaluate(gts, dets, BOXES2D_CLASSES, match_classes=BOXES2D_CLASSES)
    return {"status": "ok", "overrides": overrides, "seed": seed, "label": "x", "key": f"{overrides}-{seed}",
            "metrics": {"mAP50": 100 * m.ap50, "mAP70": 100 * m.ap70, "mAP50_95": 100 * m.map},
            "costs": {"params": 3.0e6}, "matches": matches_entry(m.match_tables)}


def test_markdown_gives_ours_beside_the_paper_and_the_bootstrap_verdict():
    adapter = tables.row_overrides(zoo.config("yolov8n_adapter"))
    fusion2 = tables.row_overrides(tables.fusion_variant(2))
    records = [record(fusion2, 0, 3.0), record(adapter, 0, 0.2), record(adapter, 1, 0.2)]
    text = tables.markdown("table6", records)
    lines = text.splitlines()
    assert "Δ mAP50_95 vs row 1 [95 % CI]" in lines[0]
    sharp, sloppy = records[1]["metrics"]["mAP50_95"], records[0]["metrics"]["mAP50_95"]
    assert sharp > sloppy + 10
    assert lines[2].startswith(f"| yolov8n_adapter fusion=2 | 2 | {records[0]['metrics']['mAP50']:.1f} (68.9)")
    assert "| - (67.8)" in lines[3]  # fusion 3: not run yet
    row1 = next(line for line in lines if line.startswith("| yolov8n_adapter | 1 |"))
    assert "above noise" in row1 and "± " in row1  # two seeds: mean ± sd
    assert "mAP@50-95 sd" in text and "over the 24 validation frames and the 2 seeds" in text


def test_a_copy_is_within_noise_and_old_records_say_how_to_get_intervals():
    fusion2 = tables.row_overrides(tables.fusion_variant(2))
    fusion3 = tables.row_overrides(tables.fusion_variant(3))
    records = [record(fusion2, 0, 1.0), record(fusion3, 0, 1.0)]
    assert "+0.0 [+0.0, +0.0] within noise" in tables.markdown("table6", records)
    bare = [{k: v for k, v in r.items() if k != "matches"} for r in records]
    assert "`python -m search.rescore RUN_DIR` adds them" in tables.markdown("table6", bare)


def test_unknown_table_is_refused():
    with pytest.raises(SystemExit, match="unknown table"):
        tables.table_rows("table9")


def test_the_shipped_record_keeps_every_row_s_trials_and_verdicts_without_match_tables():
    fusion2 = tables.row_overrides(tables.fusion_variant(2))
    adapter = tables.row_overrides(zoo.config("yolov8n_adapter"))
    records = [record(fusion2, 0, 3.0), record(adapter, 0, 0.2)]
    for r in records:
        r["environment"] = {"versions": {"jax": "0.10.2"}}
    out = tables.table_record("table6", records, "python -m experiments.yolo_rd_tables table6", "quick")
    labels = [row["label"] for row in out["rows"]]
    assert labels == [label for label, _, _ in tables.table_rows("table6")]
    assert not out["complete"]  # fusion option 3 has no trial yet
    first = out["rows"][0]["trials"][0]
    assert first["metrics"] == records[0]["metrics"] and first["environment"]["versions"]["jax"] == "0.10.2"
    assert "matches" not in first and out["rows"][1]["trials"] == []
    assert out["bootstrap"]["delta"]["yolov8n_adapter"]["ci95"][0] > 0
    assert out["markdown"] == tables.markdown("table6", records) and out["assign_small_side"] == [8.0, 16.0]
    json.dumps(out, allow_nan=False)  # plain JSON: it ships in the repository


def test_rows_names_a_subset_and_an_unknown_row_is_refused_by_name(tmp_path):
    with pytest.raises(SystemExit, match=r"--rows: no row \['yolov8x'\] in table3"):
        tables.main(["table3", "--rows", "yolov8n,yolov8x", "--out", str(tmp_path)])
    assert not (tmp_path / "journal.jsonl").exists()  # refused before anything ran

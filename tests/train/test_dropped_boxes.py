"""Boxes that RD and camera batches cut off for want of slots reach metrics.jsonl and a warning
(train/dropped_boxes.py); the loop's own use of it is checked by tests/modalities/image/test_image_fit.py's run."""

import logging

from dsfec_jax.data.rd.batches import RDBatchStream
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.train.dropped_boxes import DroppedBoxes


def test_rows_count_the_boxes_cut_off_since_the_previous_row_and_the_first_drop_warns_once(caplog):
    # two synthetic maps of two boxes each, one slot per map: every batch of both cuts off two boxes
    stream = RDBatchStream(load_rd_samples("synthetic", "train", 2, seed=1), 2, seed=3, augment=None,
                           representation=RDRepresentation(fit="resize", input_hw=(64, 32)), max_boxes=1)
    batch = stream.batch(0)  # every batch holds both maps: one built stands for all (a batch costs seconds)
    assert batch["stats"]["dropped_boxes"] == 2
    dropped, rows = DroppedBoxes("yolov8n"), []
    with caplog.at_level(logging.WARNING, logger="dsfec_jax.train.dropped_boxes"):
        for step in range(4):
            dropped.add(step, batch)
            if step % 2 == 1:  # a row every second step
                rows.append(dropped.row())
    assert rows == [{"dropped_boxes": 4}, {"dropped_boxes": 4}]
    warnings = [r.getMessage() for r in caplog.records if r.name == "dsfec_jax.train.dropped_boxes"]
    assert len(warnings) == 1 and "yolov8n: training batch 0 cut off 2 ground-truth box(es)" in warnings[0]
    assert "max_boxes=1" in warnings[0]


def test_a_stream_that_drops_nothing_logs_zero_and_one_without_the_stat_no_column(caplog):
    full = DroppedBoxes("m")
    full.add(0, {"stats": {"boxes": 3, "dropped_boxes": 0}, "targets": {}})
    assert full.row() == {"dropped_boxes": 0}
    points = DroppedBoxes("m")
    points.add(0, {"stats": {"pillars": 10}, "targets": {}})
    assert points.row() == {} and not caplog.records

"""Ground-truth boxes that training batches cut off for want of slots, made visible.

RD and camera batches pad each image's boxes to a fixed count M (the `max_boxes` of
data/rd/batches.py and models/camera/targets.py, so the jitted step compiles once) and count the
boxes a crowded image loses in stats['dropped_boxes']. A run that silently trains without some of
its ground truth learns a different task, so the loop writes the count to metrics.jsonl (the boxes
cut off since the previous row) and warns once per run, at the first batch that loses any, with
the count and the cap. Streams without the stat (point clouds) add no column. With several
processes each counts the rows it built, and the row sums them over the processes.
"""

from __future__ import annotations

import logging

import jax
import numpy as np

log = logging.getLogger(__name__)


class DroppedBoxes:
    """Counts stats['dropped_boxes'] between metrics rows; warns at the first batch that drops any."""

    def __init__(self, model: str):
        self.model = model
        self.reported = False  # the stream counts dropped boxes at all
        self.since_row = 0
        self.warned = False

    def add(self, step: int, batch: dict) -> None:
        stats = batch.get("stats") or {}
        if "dropped_boxes" not in stats:
            return
        self.reported = True
        count = int(stats["dropped_boxes"])
        self.since_row += count
        if count and not self.warned:
            self.warned = True
            cap = batch["targets"]["gt_mask"].shape[-1]
            log.warning("%s: training batch %d cut off %d ground-truth box(es): an image had more than "
                        "max_boxes=%d; training goes on without them (metrics.jsonl 'dropped_boxes' counts them "
                        "per row; warned once per run): raise max_boxes to keep them", self.model, step, count, cap)

    def row(self) -> dict:
        """The metrics row's column ({} for a stream without the stat); restarts the count."""
        if not self.reported:
            return {}
        count, self.since_row = self.since_row, 0
        if jax.process_count() > 1:  # every process writes a row at the same step: a collective is safe
            from jax.experimental import multihost_utils

            count = int(np.sum(multihost_utils.process_allgather(np.int64(count))))
        return {"dropped_boxes": count}

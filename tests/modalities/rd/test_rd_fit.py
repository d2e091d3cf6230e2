"""Training the YOLO-RD family: a few steps lower the loss, and a resumed run ends with the parameters
of an uninterrupted one. Tiny 64x32 inputs; each compiled step of YOLOv8n costs ~15 s here, so one
run serves both checks (`fit` -> fit_rd -> validation is exercised by tests/modalities/rd/test_rd_cli.py's round trip)."""

import json

import jax
import numpy as np

from dsfec_jax import zoo
from dsfec_jax.data.rd.batches import RDBatchStream
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.train.loop import RunSpec, train
from dsfec_jax.train.schedules import get_schedule

TINY = RDRepresentation(fit="resize", input_hw=(64, 32))


def test_steps_lower_the_loss_and_a_resumed_run_ends_where_the_straight_one_does(tmp_path):
    # two samples in batches of two: every batch holds the same maps, so the loss must fall
    stream = RDBatchStream(load_rd_samples("synthetic", "train", 2, seed=1), 2, seed=3, augment=None,
                           representation=TINY)
    assert stream.batch(0)["targets"]["gt_mask"].any()
    det = zoo.create("yolov8n")
    schedule = get_schedule("quick", learning_rate=2e-3, warmup_steps=1)

    def run(name, stop_at=None):
        spec = RunSpec(tmp_path / name, schedule, seed=0, total_steps=8, stop_at=stop_at, log_every=1,
                       ckpt_every=100, progress=False)
        return train(det, stream, spec, {"test": True})[0]

    straight = run("straight")
    rows = [json.loads(l) for l in (tmp_path / "straight" / "metrics.jsonl").read_text().splitlines()]
    losses = [r["loss"] for r in rows]
    assert np.isfinite(losses).all() and all(r["foreground"] > 0 for r in rows)
    assert losses[-1] < 0.9 * losses[0], losses
    run("resumed", stop_at=3)
    resumed = run("resumed")
    assert int(resumed["step"]) == int(straight["step"]) == 8
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7), straight["params"],
                 resumed["params"])

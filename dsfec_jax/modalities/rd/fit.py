"""Train a range-Doppler zoo detector (the YOLO-RD family) on RD samples, validating with the
family's protocol (COCO mAP@50 headline, evaluate_rd): the rd modality's `fit` verb (`dsfec train`
and search trials reach it through the Modality record, as they reach the point-cloud families').

Batches come from data.rd.batches.RDBatchStream (batch s a pure function of (seed, s): resumed runs
see the same data); the loop (train.loop) is the shared one: resumable run directory, JSONL metrics,
last-N and best checkpoints, background batch building.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

from ... import zoo
from ...core.provenance import jsonable
from ...data.rd.augment import RDAugment
from ...data.rd.batches import DEFAULT_MAX_BOXES, RDBatchStream
from ...data.rd.representations import RDRepresentation
from ...data.rd.sample import RDSample
from ..checks import require_modality
from ..pictures import training_picture
from .evaluate import PROTOCOLS
from .predict import RDPredictor
from ...train.ema import evaluated
from ...train.loop import RunSpec, run_record, train
from ...train.schedules import Schedule


def fit_rd(cfg, samples: Sequence[RDSample], val: Sequence[RDSample], schedule: Schedule, run_dir: str | Path,
           seed: int = 0, steps: int | None = None, augment: bool = True, eval_every: int | None = 200,
           run_info: dict | None = None, progress: bool = True, init_variables: dict | None = None, *,
           overrides: dict | None = None, match_classes: Sequence[str] = (),
           representation: RDRepresentation = RDRepresentation(),
           max_boxes: int = DEFAULT_MAX_BOXES) -> tuple[zoo.Detector, dict, dict]:
    """Train (or resume) a detector of config `cfg` in run_dir -> (detector, final state, val scores).
    run.json records `cfg.name` and `overrides` (what the caller asked for; default zoo.overrides_of(cfg)).
    `match_classes` (the protocol's validate): the scores also carry the final validation's
    "match_tables", kept out of the logged metrics."""
    det = zoo.Detector(cfg)
    family = require_modality(cfg, "rd", "fit_rd")
    overrides = zoo.overrides_of(cfg) if overrides is None else overrides
    stream = RDBatchStream(samples, schedule.batch_size, seed, RDAugment() if augment else None, representation,
                           det.config.classes, max_boxes)
    total = steps or schedule.total_steps(len(samples))
    spec = RunSpec(Path(run_dir), schedule, seed, total_steps=total, progress=progress)
    info = run_record(run_info, cfg.name, overrides, det.config, schedule, seed, total, stream.augment,
                      train_samples=len(samples), val_samples=len(val),
                      representation=jsonable(dataclasses.asdict(representation)), max_boxes=max_boxes)

    last_tables = {}  # the match tables of the latest validation, which the returned scores are
    protocol = PROTOCOLS[family.metric.name]

    def validate(state):
        scores, tables = protocol.validate(RDPredictor(det, evaluated(state), representation), val, match_classes)
        last_tables.clear()
        last_tables.update(tables)
        return scores

    def picture(state) -> bytes:  # TensorBoard's: the predict picture of the first validation sample
        from ...data.rd.figure import render_rd_figure

        return training_picture(RDPredictor(det, evaluated(state), representation), val, lambda s: s.sample_id,
                                lambda s, found, keep, title: render_rd_figure(
                                    s, found.select(keep), det.config.classes, representation.colormap, title))

    state, scores = train(det, stream, spec, info, validate, eval_every or total, init_variables=init_variables,
                          best_key=family.metric.headline, picture=picture)
    scores = scores if scores is not None else validate(state)
    return det, state, {**scores, "match_tables": dict(last_tables)} if last_tables else scores

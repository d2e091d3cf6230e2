"""Train a range-Doppler zoo detector (the YOLO-RD family) on RD samples, validating with the
family's protocol (COCO mAP@50 headline, evaluate_rd): `train.fit.fit` hands RD models here, so
`dsfec train` and search trials reach it the same way as the point-cloud families.

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
from ..points.evaluate import validate as run_validation
from .predict import RDPredictor
from ...train.loop import RunSpec, run_record, train
from ...train.schedules import Schedule


def fit_rd(model: str, overrides: dict, samples: Sequence[RDSample], val: Sequence[RDSample], schedule: Schedule,
           run_dir: str | Path, seed: int = 0, steps: int | None = None, augment: bool = True,
           eval_every: int | None = 200, run_info: dict | None = None, progress: bool = True,
           init_variables: dict | None = None, representation: RDRepresentation = RDRepresentation(),
           max_boxes: int = DEFAULT_MAX_BOXES, match_classes: Sequence[str] = ()) -> tuple[zoo.Detector, dict, dict]:
    """Train (or resume) `model` with `overrides` in run_dir -> (detector, final state, val scores).
    `match_classes` (evaluate.validate's): the scores also carry the final validation's
    "match_tables", kept out of the logged metrics."""
    det = zoo.create(model, **overrides)
    family = zoo.require_modality(det.config, "rd", "fit_rd")
    stream = RDBatchStream(samples, schedule.batch_size, seed, RDAugment() if augment else None, representation,
                           det.config.classes, max_boxes)
    total = steps or schedule.total_steps(len(samples))
    spec = RunSpec(Path(run_dir), schedule, seed, total_steps=total, progress=progress)
    info = run_record(run_info, model, overrides, det.config, schedule, seed, total, stream.augment,
                      train_samples=len(samples), val_samples=len(val),
                      representation=jsonable(dataclasses.asdict(representation)), max_boxes=max_boxes)

    last_tables = {}  # the match tables of the latest validation, which the returned scores are

    def validate(state):
        variables = {"params": state["params"], "batch_stats": state["batch_stats"]}
        scores, tables = run_validation(family.metric.name, RDPredictor(det, variables, representation), val,
                                        match_classes)
        last_tables.clear()
        last_tables.update(tables)
        return scores

    state, scores = train(det, stream, spec, info, validate, eval_every or total, init_variables=init_variables,
                          best_key=family.metric.headline)
    scores = scores if scores is not None else validate(state)
    return det, state, {**scores, "match_tables": dict(last_tables)} if last_tables else scores

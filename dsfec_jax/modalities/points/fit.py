"""Train a point-cloud zoo detector on frames with a schedule, validating on held-out frames with
the family's protocol: the points modality's `fit` verb (`dsfec train` and search trials reach it
through the Modality record)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

from ... import zoo
from ...data.points.augment import AugmentConfig
from ...data.batches import BatchStream, training_windows
from ...data.points.frame import Frame
from ...data.points.pillarize import PillarSpec, pillar_budget
from ..pictures import training_picture
from .evaluate import PROTOCOLS
from .predict import Predictor
from ...core.provenance import jsonable, versions
from ...train.ema import evaluated
from ...train.loop import RunSpec, train
from ...train.schedules import Schedule


def state_variables(state: dict) -> dict:
    """What a validation runs: the weight average's variables in a run with --ema (train/ema.py)."""
    return evaluated(state)


def _check_counts(counts: dict) -> None:
    """Training on, or validating with, nothing gives a number that means nothing: refuse it.
    (`steps=None` means the schedule's length; 0 is refused, not read as None.)"""
    bad = [f"{v} {k}" for k, v in counts.items() if v is not None and v < 1]
    if bad:
        raise ValueError(f"fit: {', '.join(bad)}; expected at least 1")


def window_detectors(cfg, window: int | None, sizing_frames=None) -> list:
    """The detector of each training window (`window` cells; None: the whole grid) of config `cfg`.
    With `sizing_frames`, pillar slots are sized to them (no pillar lost, far less padding:
    pillar_budget); without, the config's max_pillars."""
    slots = cfg.max_pillars if sizing_frames is None else pillar_budget(sizing_frames, cfg.max_pillars)
    return [zoo.Detector(dataclasses.replace(cfg, grid=g, max_pillars=slots)) for g in training_windows(cfg.grid, window)]


def fit(cfg, frames: Sequence[Frame], val: Sequence[Frame], schedule: Schedule, run_dir: str | Path, seed: int = 0,
        steps: int | None = None, augment: bool = True, eval_every: int | None = 200, run_info: dict | None = None,
        progress: bool = True, init_variables: dict | None = None, *, overrides: dict | None = None,
        match_classes: Sequence[str] = (), window: int | None = 96,
        window_sampling: str = "cycle") -> tuple[zoo.Detector, dict, dict]:
    """Train (or resume) a detector of config `cfg` in run_dir -> (detector, final state, val headline).
    run.json records `cfg.name` and `overrides` (what the caller asked for; default zoo.overrides_of(cfg)).
    `init_variables`: start from these trained variables where modules match (train.warm_start);
    `window`: training windows of that many cells (None: the whole grid); `window_sampling`: how
    steps pick their training window (data.batches.BatchStream); `match_classes` (the protocol's
    validate): the headline also carries the last validation's "match_tables" (evaluate.score),
    kept out of the logged metrics."""
    _check_counts({"training frames": len(frames), "validation frames": len(val), "steps": steps})
    det = zoo.Detector(cfg)
    family = zoo.family_of(cfg)
    overrides = zoo.overrides_of(cfg) if overrides is None else overrides
    windows = window_detectors(cfg, window, frames)
    # A family whose network takes each window's origin as an input (RadarNeXt) trains every
    # window with one compiled step (its 0.16 m grid needs 16 windows of 96 cells); the others
    # (DSFEC) compile one step per window.
    origin = family.points.origin_input
    stream = BatchStream(frames, [PillarSpec.of(w.config) for w in windows], family.points.targets(cfg),
                         schedule.batch_size, seed, AugmentConfig() if augment else None,
                         origin_input=origin, window_sampling=window_sampling)
    total = steps or schedule.total_steps(len(frames))
    spec = RunSpec(Path(run_dir), schedule, seed, total_steps=total, progress=progress)
    info = {**(run_info or {}), "model": cfg.name, "overrides": jsonable(overrides),
            "config": jsonable(dataclasses.asdict(cfg)), "schedule": dataclasses.asdict(schedule), "seed": seed,
            "steps": total, "train_frames": len(frames), "val_frames": len(val),
            "windows": [[w.config.grid.x_range, w.config.grid.y_range] for w in windows], "train_pillars": windows[0].config.max_pillars,
            "window_sampling": window_sampling, "versions": versions()}

    last_tables = {}  # the match tables of the latest validation, which the returned headline is
    protocol = PROTOCOLS[family.metric.name]

    def validate(state):  # the family's protocol: headline figures plus per-class ones (small enough to log)
        scores, tables = protocol.validate(Predictor(det, state_variables(state)), val, match_classes)
        last_tables.update(tables)
        return scores

    def picture(state) -> bytes:  # TensorBoard's: the predict picture (BEV) of the first validation frame
        from ...data.points.bev_figure import render_bev_figure

        predictor = Predictor(det, state_variables(state))
        return training_picture(predictor, val, lambda f: f.frame_id, lambda f, found, keep, title: render_bev_figure(
            f, predictor.spec.grid, found.boxes.select(keep), found.scores[keep], predictor.class_names, title))

    # with origin inputs one network shaped like a window (windows[0]) trains on every window
    state, scores = train(windows[0] if origin else det, stream, spec, info, validate, eval_every or total,
                          window_detectors=None if origin else windows,
                          init_variables=init_variables, best_key=family.metric.headline, picture=picture)
    scores = scores if scores is not None else validate(state)
    return det, state, {**scores, "match_tables": dict(last_tables)} if last_tables else scores

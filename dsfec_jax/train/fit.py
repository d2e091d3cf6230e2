"""Train a zoo detector on frames with a schedule, validating on held-out frames: the one
training entry point that `dsfec train` and search trials share."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Sequence

from .. import zoo
from ..data.augment import AugmentConfig
from ..data.batches import BatchStream, training_windows
from ..data.frame import Frame
from ..data.pillarize import PillarSpec
from ..evaluate import evaluate
from ..models.dsfec import HEAD_NAMES
from ..predict import Predictor
from ..profile.environment import versions
from .loop import RunSpec, train
from .schedules import Schedule


def jsonable(obj):
    return json.loads(json.dumps(obj, default=lambda o: dataclasses.asdict(o) if dataclasses.is_dataclass(o) else str(o)))


def state_variables(state: dict) -> dict:
    return {"params": state["params"], "batch_stats": state["batch_stats"]}


def fit(model: str, overrides: dict, frames: Sequence[Frame], val: Sequence[Frame], schedule: Schedule,
        run_dir: str | Path, seed: int = 0, steps: int | None = None, window: int | None = 96,
        augment: bool = True, eval_every: int | None = 200, run_info: dict | None = None,
        progress: bool = True, init_variables: dict | None = None) -> tuple[zoo.Detector, dict, dict]:
    """Train (or resume) `model` with `overrides` in run_dir -> (detector, final state, val headline).
    `init_variables`: start from these trained variables where modules match (train.warm_start)."""
    det = zoo.create(model, **overrides)
    cfg = det.config
    if cfg.family != "dsfec":  # the CenterHead targets and losses are not wired into this loop yet
        raise NotImplementedError(f"{model}: training is implemented for the dsfec family; {cfg.family!r} "
                                  "models can be built, re-parameterized, profiled and evaluated")
    windows = [zoo.create(model, **{**overrides, "grid": g}) for g in training_windows(cfg.grid, window)]
    stream = BatchStream(frames, [PillarSpec.of(w.config) for w in windows], dict(zip(HEAD_NAMES, cfg.head_classes)),
                         cfg.output_stride, schedule.batch_size, seed, AugmentConfig() if augment else None)
    total = steps or schedule.total_steps(len(frames))
    spec = RunSpec(Path(run_dir), schedule, seed, total_steps=total, progress=progress)
    info = {**(run_info or {}), "model": model, "overrides": jsonable(overrides),
            "config": jsonable(dataclasses.asdict(cfg)), "schedule": dataclasses.asdict(schedule), "seed": seed,
            "steps": total, "train_frames": len(frames), "val_frames": len(val),
            "windows": [[w.config.grid.x_range, w.config.grid.y_range] for w in windows], "versions": versions()}

    def validate(state):  # headline figures plus every class's mAP and AP@4 (small enough to log)
        result = evaluate(Predictor(det, state_variables(state)), val)
        m = result.pop("metrics")
        return {**result, "class_mAP": m["class_mAP"], "AP@4": m.get("AP@4", {})}

    state, scores = train(det, stream, spec, info, validate, eval_every or total, window_detectors=windows,
                          init_variables=init_variables)
    return det, state, scores if scores is not None else validate(state)

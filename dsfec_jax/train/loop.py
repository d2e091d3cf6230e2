"""The training loop: resumable run directories, JSONL metrics, last-N and best checkpoints.

RUN_DIR/
  run.json                 model config, schedule, seed, data description, versions; written when
                           the run starts and never rewritten: a resume must ask for the same setup
                           (else RunMismatch) and is appended to its "resumes" list
  metrics.jsonl            one JSON line per logged step (and per evaluation); RD and camera rows
                           count the ground-truth boxes cut off since the previous row (dropped_boxes)
  checkpoints/last/step_0000300/   the last `keep` states (Orbax; see core.run_checkpoints)
  checkpoints/best/step_0000200/   the state with the best validation score
  events.out.tfevents.*    TensorBoard: the metrics rows, learning rates, validations and a
                           prediction picture per validation (train/tensorboard.py)

A state may keep a weight average ('ema', train/ema.py: the schedule's `ema`), which is then
what validations score and checkpoints ship.

A kill at any point leaves a resumable directory: Orbax finishes a checkpoint by renaming it (an
incomplete one is never listed, and removed), a torn last metrics line is dropped.

The host never stalls the step: batches are built ahead by a background worker
(dsfec_jax.data.prefetch) and handed over as ready XLA buffers (train.step.batch_on_device), and
the losses stay on the device until a log, evaluation or checkpoint step reads them together
(train.loss_watch), which is also where a non-finite loss stops the run, before any diverged
state is evaluated or saved. Under JAX's default async dispatch the loop queues the next step
without waiting; the project's commands run each step inline (core/host_memory.py), which keeps
XLA's temporary buffer between steps.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import logging
import os
import time
from pathlib import Path
from typing import Callable

import jax
from tqdm import tqdm

from ..core import atomic, progress
from ..core.provenance import jsonable, versions
from ..core.run_checkpoints import RunCheckpoints
from ..data.batches import BatchStream
from ..data.prefetch import Prefetcher
from . import ema as weight_ema
from .dropped_boxes import DroppedBoxes
from .loss_watch import LossWatch, NonFiniteLoss
from . import parallel
from .schedules import Schedule, optimizer
from .step import init_state, make_train_step
from .tensorboard import Board, schedule_rates


log = logging.getLogger(__name__)

# run.json fields that say how a run was launched, not what it trains: a resume may differ in them
LAUNCH_FIELDS = ("command", "versions", "resumes", "parallel", "tensorboard")  # parallel: devices and mesh (same global batch)
SHOWN_DIFFERENCES = 8  # a changed model differs in many config fields: name the first few
# What the first step of a run (and of each training window) costs before the bar moves: XLA
# compiling the step. Measured on the 2-core dev box (`dsfec train`, `python -m search.nas`):
# 21-27 s for each of dsfec_s's 4 windows at load 3, 50 s for the YOLOv8n-Adapter NAS supernet
# at load 3 and 152 s at load 9
COMPILE_USUAL = "20 s to 2.5 min on 2 CPU cores, by model and machine load"


class TrainingDiverged(RuntimeError):
    pass


class RunMismatch(ValueError):
    """The command asks a run directory for a different setup than the one it was started with."""


@dataclasses.dataclass
class RunSpec:
    run_dir: Path
    schedule: Schedule
    seed: int = 0
    total_steps: int = 0          # the planned length (sets the learning-rate schedule)
    stop_at: int | None = None    # stop early (e.g. to test resume); None = total_steps
    log_every: int = 10
    ckpt_every: int = 100
    keep: int = 3
    progress: bool = True


def run_record(run_info: dict | None, model: str, overrides: dict, config, schedule: Schedule, seed: int,
               steps: int, augment, **fields) -> dict:
    """run.json's content for a fit: the caller's `run_info` (command, data), the model, its
    overrides and whole config, the schedule, seed and length, the augmentation settings (a
    dataclass, or None for none), the fit's own `fields` and the versions."""
    return {**(run_info or {}), "model": model, "overrides": jsonable(overrides),
            "config": jsonable(dataclasses.asdict(config)), "schedule": jsonable(dataclasses.asdict(schedule)),
            "seed": seed, "steps": steps, **fields,
            "augment": jsonable(dataclasses.asdict(augment)) if augment is not None else None,
            "versions": versions()}


def _differences(old, new, prefix: str = "") -> list[tuple[str, object, object]]:
    """(dotted field, old, new) for every leaf where two run.json trees differ."""
    if not (isinstance(old, dict) and isinstance(new, dict)):
        return [] if old == new else [(prefix, old, new)]
    keys = list(old) + [k for k in new if k not in old]
    absent = "<absent>"
    return [d for k in keys for d in _differences(old.get(k, absent), new.get(k, absent), f"{prefix}{k}.")]


def _added_default(path: str, old, new, config_type: type | None = None) -> bool:
    """A field added to Schedule (or to the model's config dataclass) after the run started, at its
    default value: the run trained with that value all along (e.g. optimizer 'adamw', or YOLO's
    elastic width ratios at 1), so its resume is not a new setup."""
    for prefix, cls in (("schedule.", Schedule), ("config.", config_type)):
        if cls is not None and path.startswith(prefix):
            defaults = {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}
            field = path[len(prefix):-1]
            return old == "<absent>" and field in defaults and json.loads(json.dumps(defaults[field])) == new
    return False


def _setup(info: dict) -> dict:
    return {k: v for k, v in info.items() if k not in LAUNCH_FIELDS}


def _show(diffs: list, side: int) -> str:
    shown = [f"{path[:-1]}={json.dumps(d[side])[:60]}" for path, *d in diffs[:SHOWN_DIFFERENCES]]
    more = len(diffs) - SHOWN_DIFFERENCES
    return ", ".join(shown) + (f" (and {more} more)" if more > 0 else "")


def _started_with(run_dir: Path, run_info: dict, config_type: type | None = None) -> dict | None:
    """The run.json of an existing run (None for a new one); RunMismatch when `run_info` asks for a
    different setup. A run killed before its first checkpoint is checked too: run.json says what
    the directory is for, and a new setup belongs in a new directory."""
    path = run_dir / "run.json"
    if not path.exists():
        return None
    try:
        old = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise RunMismatch(f"{path}: not readable JSON ({err}); cannot tell which run this directory holds") from err
    diffs = [d for d in _differences(_setup(old), _setup(json.loads(json.dumps(run_info))))
             if not _added_default(*d, config_type)]
    if diffs:
        raise RunMismatch(f"{path}: this run was started with {_show(diffs, 0)}; the command asks "
                          f"{_show(diffs, 1)}. Use a new run directory (--run-dir) for a different setup, "
                          f"or delete {run_dir} to start over.{weight_ema.resume_hint(diffs)}")
    return old


def _record_start(run_dir: Path, run_info: dict, previous: dict | None, step: int) -> None:
    """A new run writes run.json; a resume keeps the original (the provenance) and appends itself
    to its "resumes" list, with its own command line and versions."""
    if previous is None:
        atomic.write_json(run_dir / "run.json", run_info)
        return
    resume = {"from_step": step, "at": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
              **{k: run_info[k] for k in LAUNCH_FIELDS if k in run_info and k != "resumes"}}
    atomic.write_json(run_dir / "run.json", {**previous, "resumes": [*previous.get("resumes", []), resume]})


def _trim_metrics(path: Path, step: int) -> None:
    """Drop log lines past the resumed step, so a resumed run's log reads like one run. A kill
    while a line was written leaves it torn: the last line may be dropped, any other must parse."""
    if not path.exists():
        return
    lines = [l for l in path.read_text().splitlines() if l.strip()]
    kept = []
    for i, line in enumerate(lines):
        try:
            row = json.loads(line)
        except json.JSONDecodeError as err:
            if i < len(lines) - 1:
                raise ValueError(f"{path}: line {i + 1} is not JSON ({err}): {line[:80]!r}") from err
            log.warning("%s: dropped its torn last line (killed while writing it): %r", path, line[:80])
            continue
        if row.get("step", 0) <= step:
            kept.append(line)
    atomic.write_text(path, "".join(l + "\n" for l in kept))


def train(detector, stream: BatchStream, spec: RunSpec, run_info: dict,
          evaluate: Callable[[dict], dict] | None = None, eval_every: int | None = None,
          best_key: str = "car_mAP", window_detectors: list | None = None,
          init_variables: dict | None = None,
          before_eval: Callable[[dict], dict] | None = None,
          picture: Callable[[dict], bytes] | None = None) -> tuple[dict, dict | None]:
    """Train (or resume) in spec.run_dir -> (final state, last evaluation or None).
    `evaluate(state) -> metrics` runs every `eval_every` steps and at the end; `before_eval(state)
    -> state` (e.g. train.precise_bn) runs just before it, and its state is the one evaluated,
    saved and trained on (a deterministic function of the state: resumes stay exact).
    `window_detectors[i]` (same weights, grid = the stream's window i) trains on window i.
    `init_variables` (trained variables of this or a related network) seed a fresh run module by
    module (see warm_start); a resumed run ignores them. `picture(state)` -> PNG bytes of the
    model's predictions, logged to TensorBoard with each validation (train/tensorboard.py; event
    files unless run_info says "tensorboard": false)."""
    layout = parallel.layout()  # data parallel over the mesh (train/parallel.py); one device: as before
    layout.check_batch(stream.batch_size)
    run_info = {**run_info, "parallel": layout.record()}
    writer = parallel.is_writer()
    if writer:
        spec.run_dir.mkdir(parents=True, exist_ok=True)
    previous = _started_with(spec.run_dir, run_info, type(detector.config))
    # a detector may bring its own optimizer (a sandwich-sampled supernet accumulates over its cycle)
    tx = (detector.optimizer if hasattr(detector, "optimizer") else optimizer)(spec.schedule, spec.total_steps)
    ckpts = RunCheckpoints(spec.run_dir, spec.keep, best_key)
    with progress.stage(f"initialising {detector.name} (compiling its initialisation)", enabled=spec.progress):
        fresh = weight_ema.with_ema(init_state(detector, tx, jax.random.key(spec.seed), init_variables),
                                    bool(spec.schedule.ema))
        # restored in the fresh state's placement (the mesh's), then process 0's values everywhere
        state = layout.replicate(ckpts.restore(layout.replicate(fresh)))
    start = int(state["step"])
    log_path = spec.run_dir / "metrics.jsonl"
    if writer:
        _record_start(spec.run_dir, run_info, previous, start)
        _trim_metrics(log_path, start)
    # a detector may bring its own step (a depth supernet keeps its idle blocks still)
    step_fns = [d.make_train_step(tx) if hasattr(d, "make_train_step") else make_train_step(d, tx)
                for d in (window_detectors or [detector])]
    step_fns = [layout.step(f) for f in step_fns]
    end = spec.total_steps if spec.stop_at is None else min(spec.stop_at, spec.total_steps)
    best = ckpts.best_score()
    scores = None
    losses = LossWatch()
    dropped = DroppedBoxes(detector.name)
    t0 = time.perf_counter()

    def ready_batch(step: int) -> dict:  # built, and copied into XLA buffers, in the worker
        return layout.local_batch(stream, step)

    rates = None if hasattr(detector, "optimizer") else schedule_rates(spec.schedule, spec.total_steps)
    with ckpts, open(log_path if writer else os.devnull, "a") as log, Prefetcher(ready_batch, range(start, end)) as batches, \
            Board(spec.run_dir, start, rates, writer and run_info.get("tensorboard", True)) as board:
        bar = tqdm(batches, initial=start, total=end, disable=not spec.progress, desc=detector.name)
        compiled = set()  # the step functions (one per window) that have run: the first call compiles
        for step, batch in bar:
            window = batch["window"] % len(step_fns)
            with progress.stage(_compiling(detector.name, window, len(step_fns)), usual=COMPILE_USUAL,
                                enabled=spec.progress and window not in compiled):
                state, metrics = step_fns[window](state, {"inputs": batch["inputs"], "targets": batch["targets"]})
            compiled.add(window)
            losses.add(step, metrics["loss"])
            dropped.add(step, batch)
            done = step + 1
            log_step = done % spec.log_every == 0 or done == end
            eval_step = evaluate is not None and eval_every and (done % eval_every == 0 or done == end)
            save_step = done % spec.ckpt_every == 0 or done == end
            if not (log_step or eval_step or save_step):
                continue  # nothing to read: the next step is queued without waiting for this one
            loss = _checked_loss(losses, detector.name, ckpts)  # before any state is evaluated or saved
            rate = stream.batch_size * (done - start) / (time.perf_counter() - t0)
            if log_step:
                bar.set_postfix(loss=f"{loss:.3f}", fps=f"{rate:.1f}")
                values = {k: float(v) for k, v in jax.device_get(metrics).items()}
                row = {"step": done, "frames_per_s": round(rate, 2), **values, **dropped.row()}
                log.write(json.dumps(row) + "\n")
                log.flush()
                board.training(done, row)
            if eval_step:
                with progress.stage(f"validating {detector.name} at step {done}"
                                    + ("" if scores else " (the first validation compiles the predictor)"),
                                    enabled=spec.progress):
                    if before_eval is not None:
                        state = layout.replicate(before_eval(layout.on_host(state)))
                    scores = evaluate(layout.on_host(state))
                log.write(json.dumps({"step": done, "eval": scores}) + "\n")
                log.flush()
                board.validation(done, scores, picture and (lambda: picture(layout.on_host(state))))
                score = scores.get(best_key)  # None: nothing to score (e.g. no ground truth)
                if score is not None and score > best:  # every process: Orbax saves collectively
                    best = scores[best_key]
                    ckpts.save_best(done, state, best, {"eval": scores})
            if save_step:
                ckpts.save(done, state, {"loss": loss})
    return state, scores


def _compiling(name: str, window: int, windows: int) -> str:
    where = f" (training window {window + 1} of {windows})" if windows > 1 else ""
    return f"compiling {name}'s training step{where}"


def _checked_loss(losses: LossWatch, name: str, ckpts: RunCheckpoints) -> float:
    """The latest loss; TrainingDiverged naming the first non-finite step since the last check."""
    try:
        return losses.check()
    except NonFiniteLoss as err:
        last = ckpts.latest()
        raise TrainingDiverged(f"{name}: loss is {err.value} at step {err.step}; stopped. Last good "
                               f"checkpoint: {last or 'none (diverged before the first)'}") from err


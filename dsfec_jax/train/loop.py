"""The training loop: resumable run directories, JSONL metrics, last-N and best checkpoints.

RUN_DIR/
  run.json                 model config, schedule, seed, data description, versions
  metrics.jsonl            one JSON line per logged step (and per evaluation)
  checkpoints/step_0000300.msgpack (+ .json)   the last `keep` states
  checkpoints/best.msgpack (+ .json)           the state with the best validation score
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Callable

import jax
import numpy as np
from tqdm import tqdm

from .. import atomic, checkpoint
from ..data.batches import BatchStream
from .losses import LossConfig
from .schedules import Schedule, optimizer
from .step import init_state, make_train_step


class TrainingDiverged(RuntimeError):
    pass


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
    loss: LossConfig = LossConfig()
    progress: bool = True


def checkpoints(run_dir: Path) -> list[Path]:
    return sorted((run_dir / "checkpoints").glob("step_*.msgpack"))


def _restore(run_dir: Path, state: dict) -> dict:
    last = checkpoints(run_dir)
    return checkpoint.load(last[-1], state) if last else state


def _trim_metrics(path: Path, step: int) -> None:
    """Drop log lines past the resumed step, so a resumed run's log reads like one run."""
    if path.exists():
        lines = [l for l in path.read_text().splitlines() if l and json.loads(l).get("step", 0) <= step]
        atomic.write_text(path, "".join(l + "\n" for l in lines))


def _save(spec: RunSpec, state: dict, step: int, extra: dict) -> None:
    ckpt_dir = spec.run_dir / "checkpoints"
    checkpoint.save(ckpt_dir / f"step_{step:07d}.msgpack", jax.device_get(state), {"step": step, **extra})
    for old in checkpoints(spec.run_dir)[: -spec.keep]:
        old.unlink()
        checkpoint.manifest_path(old).unlink(missing_ok=True)


def train(detector, stream: BatchStream, spec: RunSpec, run_info: dict,
          evaluate: Callable[[dict], dict] | None = None, eval_every: int | None = None,
          best_key: str = "car_mAP", window_detectors: list | None = None,
          init_variables: dict | None = None) -> tuple[dict, dict | None]:
    """Train (or resume) in spec.run_dir -> (final state, last evaluation or None).
    `evaluate(state) -> metrics` runs every `eval_every` steps and at the end.
    `window_detectors[i]` (same weights, grid = the stream's window i) trains on window i.
    `init_variables` (trained variables of this or a related network) seed a fresh run module by
    module (see warm_start); a resumed run ignores them."""
    spec.run_dir.mkdir(parents=True, exist_ok=True)
    atomic.write_json(spec.run_dir / "run.json", run_info)
    tx = optimizer(spec.schedule, spec.total_steps)
    state = _restore(spec.run_dir, init_state(detector, tx, jax.random.key(spec.seed), init_variables))
    start = int(state["step"])
    log_path = spec.run_dir / "metrics.jsonl"
    _trim_metrics(log_path, start)
    step_fns = [make_train_step(d, tx, spec.loss) for d in (window_detectors or [detector])]
    end = spec.total_steps if spec.stop_at is None else min(spec.stop_at, spec.total_steps)
    best = _best_score(spec.run_dir, best_key)
    scores = None
    bar = tqdm(range(start, end), initial=start, total=end, disable=not spec.progress, desc=detector.name)
    t0 = time.perf_counter()
    with open(log_path, "a") as log:
        for step in bar:
            batch = stream.batch(step)
            step_fn = step_fns[batch["window"] % len(step_fns)]
            state, metrics = step_fn(state, {"inputs": batch["inputs"], "targets": batch["targets"]})
            loss = float(metrics["loss"])
            if not math.isfinite(loss):
                last = checkpoints(spec.run_dir)
                raise TrainingDiverged(f"{detector.name}: loss is {loss} at step {step}; stopped. Last good "
                                       f"checkpoint: {last[-1] if last else 'none (diverged before the first)'}")
            done = step + 1
            rate = stream.batch_size * (done - start) / (time.perf_counter() - t0)
            bar.set_postfix(loss=f"{loss:.3f}", fps=f"{rate:.1f}")
            if done % spec.log_every == 0 or done == end:
                row = {"step": done, "frames_per_s": round(rate, 2), **{k: float(v) for k, v in metrics.items()}}
                log.write(json.dumps(row) + "\n")
                log.flush()
            if evaluate is not None and eval_every and (done % eval_every == 0 or done == end):
                scores = evaluate(state)
                log.write(json.dumps({"step": done, "eval": scores}) + "\n")
                log.flush()
                if scores.get(best_key, -np.inf) > best:
                    best = scores[best_key]
                    checkpoint.save(spec.run_dir / "checkpoints" / "best.msgpack", jax.device_get(state),
                                    {"step": done, best_key: best, "eval": scores})
            if done % spec.ckpt_every == 0 or done == end:
                _save(spec, state, done, {"loss": loss})
    return state, scores


def _best_score(run_dir: Path, key: str) -> float:
    path = checkpoint.manifest_path(run_dir / "checkpoints" / "best.msgpack")
    return json.loads(path.read_text()).get(key, -np.inf) if path.exists() else -np.inf

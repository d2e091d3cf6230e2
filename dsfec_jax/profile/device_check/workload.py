"""What the device check runs of one model: a trainer as train/loop.py takes it (`init`, and
optionally its own `optimizer(schedule, total_steps)` and `make_train_step(tx)`), an inference
function, the schedule, host batches, and one first state shared by both sides.

`build(kernels)` gives the trainer and inference with the config's `kernels` replaced (None: the
config's own), so the reference side can run the textbook formulations; both sides start from
the same `initial_state` (made once, on the host), so they differ only in where and how they run.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import jax
import numpy as np

from ... import zoo
from ...train.schedules import Schedule, optimizer
from ...train.step import init_state, make_train_step


@dataclasses.dataclass(frozen=True)
class Programs:
    """The un-compiled programs of one side: `step(state, batch) -> (state, metrics)` (jitted, as
    training runs it) and `infer(state, inputs) -> outputs` (jitted, evaluation mode)."""

    step: Callable
    infer: Callable


@dataclasses.dataclass(frozen=True)
class Workload:
    """One model of the check. `kernels`: what its config asks for (None where it has no such
    field); `batches`: host pytrees {'inputs', 'targets'}; `initial_state`: host arrays."""

    model: str
    family: str
    kernels: str | None
    batches: list[dict]
    initial_state: dict
    build: Callable[[str | None], Programs]

    def input_shapes(self) -> dict:
        return {k: list(np.shape(v)) for k, v in self.batches[0]["inputs"].items()}


def trainer_programs(trainer, schedule: Schedule, total_steps: int, infer: Callable) -> Programs:
    """The step train/loop.py would run for `trainer` (its own optimizer and step where it brings
    them, else the schedule's and train/step.py's) and `infer` jitted."""
    tx = (trainer.optimizer if hasattr(trainer, "optimizer") else optimizer)(schedule, total_steps)
    step = trainer.make_train_step(tx) if hasattr(trainer, "make_train_step") else make_train_step(trainer, tx)
    return Programs(step, jax.jit(infer))


def first_state(trainer, schedule: Schedule, total_steps: int, seed: int) -> dict:
    """The training state both sides start from, as host (numpy) arrays."""
    tx = (trainer.optimizer if hasattr(trainer, "optimizer") else optimizer)(schedule, total_steps)
    return jax.device_get(init_state(trainer, tx, jax.random.key(seed)))


def on_host(batches: list[dict]) -> list[dict]:
    """Batches as host arrays with only what a step reads ('inputs', 'targets')."""
    return [jax.device_get({"inputs": b["inputs"], "targets": b["targets"]}) for b in batches]


def detector_workload(cfg, batches: list[dict], schedule: Schedule, total_steps: int, seed: int) -> Workload:
    """A zoo detector's workload: train/step.py's step with the family's loss, and the eval-mode
    forward (raw head maps: what every predictor decodes)."""

    def build(kernels: str | None) -> Programs:
        detector = zoo.Detector(cfg if kernels is None else dataclasses.replace(cfg, kernels=kernels))
        infer = lambda state, inputs: detector.apply(  # noqa: E731
            {"params": state["params"], "batch_stats": state["batch_stats"]}, inputs, train=False)
        return trainer_programs(detector, schedule, total_steps, infer)

    return Workload(cfg.name, zoo.family_of(cfg).name, getattr(cfg, "kernels", None), on_host(batches),
                    first_state(zoo.Detector(cfg), schedule, total_steps, seed), build)


def kernels_override(workload: Workload, kernels: str) -> str | None:
    """`kernels` where the workload's config has the field, else None (nothing to replace)."""
    return None if workload.kernels is None else kernels


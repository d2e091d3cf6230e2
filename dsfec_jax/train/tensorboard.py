"""TensorBoard event files beside metrics.jsonl, written by tensorboardX's SummaryWriter.

What a run logs (tags):
  train/<column>     every number of a metrics.jsonl row: loss, grad_norm, each loss part,
                     frames_per_s (throughput), dropped_boxes
  train/lr           the optimizer's learning rate for the step the row reports (train/lr/<group>
                     for the ultralytics recipe's three parameter groups), from the schedule itself
  val/<key>          every number of a validation's scores (nested dicts as val/<key>/<subkey>)
  val/predictions    the picture `dsfec predict --png-dir` draws, of the first validation item,
                     at each validation (the fit passes how to draw it)

`tensorboard --logdir runs/` shows every run directory below runs/ as one run.

Only process 0 writes (jax.process_index()): the other processes of a multi-host run train the
same replicated state. A resumed run starts a new event file whose first event purges the
steps past its checkpoint (SummaryWriter's purge_step, which TensorBoard's reader applies), so
steps logged by the killed run after its last checkpoint do not show twice; the file name
carries the step it resumes from, so two writers started within one second never share a name.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Callable

import jax
import numpy as np

from .schedules import Schedule, learning_rate, recipe_for
from .sgd_recipe import learning_rates

TRAIN, VAL = "train", "val"
PICTURE_TAG = f"{VAL}/predictions"


def schedule_rates(schedule: Schedule, total_steps: int) -> Callable[[int], dict]:
    """fn(optimizer step index, from 0) -> {tag suffix: learning rate} of the project's optimizer
    for `schedule` (train.schedules.optimizer): 'lr', or 'lr/<group>' for the sgd recipe."""
    if schedule.optimizer == "sgd":
        recipe = recipe_for(schedule, total_steps)
        return lambda step: {f"lr/{group}": rate for group, rate in learning_rates(recipe, step).items()}
    rate = learning_rate(schedule, total_steps)
    return lambda step: {"lr": rate(step)}


def numbers(tree: dict, prefix: str) -> dict[str, float]:
    """{tag: value} for every number (int, float, 0-d array) of `tree`, nested dicts joined by '/';
    strings, lists, None and booleans are not scalars to plot."""
    out = {}
    for key, value in tree.items():
        tag = f"{prefix}/{key}"
        if isinstance(value, dict):
            out.update(numbers(value, tag))
            continue
        array = np.asarray(value)
        if array.ndim == 0 and np.issubdtype(array.dtype, np.number):
            out[tag] = float(array)
    return out


def png_pixels(png: bytes) -> np.ndarray:
    """(H, W, 3) uint8 pixels of a PNG (SummaryWriter.add_image takes pixels)."""
    from PIL import Image

    with Image.open(io.BytesIO(png)) as image:
        return np.asarray(image.convert("RGB"))


class Board:
    """The run's TensorBoard writer, a no-op where nothing is written (`enabled` False, or not
    process 0). `start`: the step the run (re)starts from; `rates`: schedule_rates, or None when
    the optimizer is not the schedule's own (a detector that brings one)."""

    def __init__(self, run_dir: str | Path, start: int, rates: Callable[[int], dict] | None, enabled: bool = True):
        self.rates, self.writer = rates, None
        if enabled and jax.process_index() == 0:
            from tensorboardX import SummaryWriter

            self.writer = SummaryWriter(str(run_dir), purge_step=start + 1, filename_suffix=f".from_step_{start:07d}")

    def __enter__(self) -> "Board":
        return self

    def __exit__(self, *exc) -> None:
        if self.writer is not None:
            self.writer.close()

    def training(self, step: int, row: dict) -> None:
        """A metrics.jsonl row of training step `step` (the state after `step` updates)."""
        if self.writer is None:
            return
        scalars = numbers({k: v for k, v in row.items() if k != "step"}, TRAIN)
        if self.rates is not None:  # the update that made step `step` ran with the rate of index step - 1
            scalars.update(numbers(self.rates(step - 1), TRAIN))
        for tag, value in scalars.items():
            self.writer.add_scalar(tag, value, step)
        self.writer.flush()  # readable at once, as metrics.jsonl is

    def validation(self, step: int, scores: dict, picture: Callable[[], bytes] | None = None) -> None:
        """A validation's scores at `step`; `picture()` -> PNG bytes, drawn only when written."""
        if self.writer is None:
            return
        for tag, value in numbers(scores, VAL).items():
            self.writer.add_scalar(tag, value, step)
        if picture is not None:
            self.writer.add_image(PICTURE_TAG, png_pixels(picture()), step, dataformats="HWC")
        self.writer.flush()

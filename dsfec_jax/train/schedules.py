"""Optimizers and learning-rate schedules.

`paper` is DSFEC §4.1: Adam (beta1 0.9) with decoupled weight decay 0.01, initial learning rate
0.00348, piecewise-constant decay after 400 warm-up iterations, batch 24, 30 epochs. The paper
does not give the decay boundaries; we decay x0.1 at 2/3 and 8/9 of training (the usual
"epochs 20 and 27 of 30" choice). `quick` is a short CPU schedule for a useful model in minutes. `radarnext` is RadarNeXt's
published schedule (the warm-up length is ours).
"""

from __future__ import annotations

import dataclasses

import optax


@dataclasses.dataclass(frozen=True)
class Schedule:
    name: str
    learning_rate: float
    warmup_steps: int
    batch_size: int
    epochs: int | None = None          # paper: epochs over the training split
    steps: int | None = None           # quick: a fixed number of steps
    decay_at: tuple[float, ...] = (2 / 3, 8 / 9)  # fractions of training
    decay_factor: float = 0.1
    weight_decay: float = 0.01
    b1: float = 0.9
    clip_norm: float = 10.0

    def total_steps(self, train_frames: int) -> int:
        if self.steps is not None:
            return self.steps
        return max(1, self.epochs * (train_frames // self.batch_size))


SCHEDULES = {
    "paper": Schedule("paper", 0.00348, 400, 24, epochs=30),
    "quick": Schedule("quick", 0.002, 50, 8, steps=600),
    # RadarNeXt's public config: AdamW lr 3e-3, wd 0.01, clip 10, x0.1 at epochs 35 and 45 of 80, batch 8
    "radarnext": Schedule("radarnext", 0.003, 100, 8, epochs=80, decay_at=(35 / 80, 45 / 80)),
}


def get_schedule(name: str, **overrides) -> Schedule:
    if name not in SCHEDULES:
        raise ValueError(f"unknown schedule {name!r}; valid: {sorted(SCHEDULES)}")
    return dataclasses.replace(SCHEDULES[name], **overrides)


def learning_rate(s: Schedule, total_steps: int) -> optax.Schedule:
    """Linear warm-up, then piecewise-constant decay at the given fractions of training."""
    warmup = optax.linear_schedule(s.learning_rate / 100, s.learning_rate, max(s.warmup_steps, 1))
    boundaries = {max(int(f * total_steps) - s.warmup_steps, 1): s.decay_factor for f in s.decay_at}
    constant = optax.piecewise_constant_schedule(s.learning_rate, boundaries)
    return optax.join_schedules([warmup, constant], [s.warmup_steps])


def optimizer(s: Schedule, total_steps: int) -> optax.GradientTransformation:
    return optax.chain(
        optax.clip_by_global_norm(s.clip_norm),
        optax.adamw(learning_rate(s, total_steps), b1=s.b1, weight_decay=s.weight_decay),
    )

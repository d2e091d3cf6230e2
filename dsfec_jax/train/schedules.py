"""Optimizers and learning-rate schedules.

`paper` is DSFEC §4.1: Adam (beta1 0.9) with decoupled weight decay 0.01, initial learning rate
0.00348, piecewise-constant decay after 400 warm-up iterations, batch 24, 30 epochs. The paper
does not give the decay boundaries; we decay x0.1 at 2/3 and 8/9 of training (the usual
"epochs 20 and 27 of 30" choice). `quick` is a short CPU schedule for a useful model in minutes. `radarnext` is RadarNeXt's
published schedule (the warm-up length is ours).

`yolo_paper` and `yolo_quick` (optimizer "sgd") are the ultralytics recipe for the YOLO-on-RD family,
built by train/sgd_recipe.py: SGD lr0 0.01, Nesterov momentum 0.937, weight decay 5e-4, three
warm-up epochs (at least `warmup_steps` = 100 batches), linear per-epoch decay to lrf 0.01, gradients
summed to a nominal batch of 64 and clipped to norm 10. `yolo_paper` is the YOLOv8-Adapter paper's
profile (300 epochs, batch 64); `yolo_quick` is ultralytics' default batch 16 (4 batches per optimizer
step) for 15 epochs over ~1000 synthetic 256x64 samples (15 x 62 batches x 16 = 14,880 frames): minutes
on the 2-core CPU (the rates it was sized by: docs/range-doppler.md; `dsfec bench --train --models
yolov8n,yolov8n_adapter` re-measures them).

`yolo3_paper` (optimizer "darknet") is pjreddie/darknet cfg/yolov3-voc.cfg, the schedule the
Shuffle-YOLOv3 paper trained with on one GPU: batch 64 (darknet's subdivisions=16 only split it
into 4-image passes, the update is per 64), SGD with momentum 0.9, learning rate 0.001 with
darknet's burn_in (lr (step / 1000)^4 over the first 1000 batches, src/network.c
get_current_rate, power 4), max_batches 50200, policy steps x0.1 at 40000 and 45000 (kept as
fractions of the run, so --steps stretches them), weight decay 5e-4 on the conv kernels only
(darknet's update_convolutional_layer decays the weights, not biases or BN scales), coupled
(added to the gradient, as darknet's axpy(-decay * batch, weights, updates) does), no gradient
clipping. `yolo3_quick` is sized for the 2-core CPU: AdamW 1e-3, decoupled decay 5e-4 (SGD at
0.001 barely moves a from-scratch network in a few hundred steps), 30 warm-up steps, batch 8,
200 steps, x0.1 at 2/3 and 8/9; modalities/image/fit.py pairs it with multi-scale 320-416 (darknet's is
320-608). It takes minutes on one core (the timings: docs/camera.md, "Schedules"; `dsfec bench --train
--models shuffle_yolov3` re-measures a step).

The recipe decays per epoch: its epochs come from `epochs`, and steps_per_epoch =
max(total_steps // epochs, 1), so a `--steps` override stretches or shrinks every epoch rather than
cutting the schedule off. A step-based sgd schedule (one with `steps`) must give `epochs` as well.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import optax

from .sgd_recipe import SGDRecipe, learning_rates, make_recipe, ultralytics_sgd

OPTIMIZERS = ("adamw", "sgd", "darknet")


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
    optimizer: str = "adamw"           # "sgd": the ultralytics recipe (sgd_recipe); warmup_steps is then
                                       # the least number of warm-up batches (ultralytics: 100)
    momentum: float = 0.937            # sgd and darknet; the rest sgd only
    warmup_momentum: float = 0.8
    warmup_bias_lr: float = 0.1
    warmup_epochs: float = 3.0
    final_lr_fraction: float = 0.01    # ultralytics' lrf: the last epoch's lr is lr0 * lrf
    nominal_batch: int = 64            # ultralytics' nbs: gradients are summed up to this batch
    ema: bool = False                  # validate and ship a weight EMA (train/ema.py); `dsfec train`
                                       # sets it from Family.weight_ema unless --ema/--no-ema says

    def __post_init__(self):
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"schedule {self.name!r}: optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if self.optimizer == "sgd" and not self.epochs:
            raise ValueError(f"schedule {self.name!r}: optimizer 'sgd' decays per epoch and needs epochs "
                             f"(a positive integer, also when steps is given), got epochs={self.epochs!r}")

    def total_steps(self, train_frames: int) -> int:
        if self.steps is not None:
            return self.steps
        return max(1, self.epochs * (train_frames // self.batch_size))


SCHEDULES = {
    "paper": Schedule("paper", 0.00348, 400, 24, epochs=30),
    "quick": Schedule("quick", 0.002, 50, 8, steps=600),
    # RadarNeXt's public config: AdamW lr 3e-3, wd 0.01, clip 10, x0.1 at epochs 35 and 45 of 80, batch 8
    "radarnext": Schedule("radarnext", 0.003, 100, 8, epochs=80, decay_at=(35 / 80, 45 / 80)),
    # ultralytics/cfg/default.yaml hyperparameters with the SGD the issue names (default.yaml says "auto")
    "yolo_paper": Schedule("yolo_paper", 0.01, 100, 64, epochs=300, optimizer="sgd", weight_decay=5e-4),
    "yolo_quick": Schedule("yolo_quick", 0.01, 100, 16, epochs=15, optimizer="sgd", weight_decay=5e-4),
    # darknet's yolov3-voc.cfg (the camera family's paper profile) and its CPU-sized counterpart
    "yolo3_paper": Schedule("yolo3_paper", 0.001, 1000, 64, steps=50200, decay_at=(40000 / 50200, 45000 / 50200),
                            weight_decay=5e-4, optimizer="darknet", momentum=0.9),
    "yolo3_quick": Schedule("yolo3_quick", 0.001, 30, 8, steps=200, weight_decay=5e-4),
}


def get_schedule(name: str, **overrides) -> Schedule:
    if name not in SCHEDULES:
        raise ValueError(f"unknown schedule {name!r}; valid: {sorted(SCHEDULES)}")
    return dataclasses.replace(SCHEDULES[name], **overrides)


def recipe_for(s: Schedule, total_steps: int) -> SGDRecipe:
    """The ultralytics recipe of an sgd schedule over a run of `total_steps` batches."""
    if s.optimizer != "sgd":
        raise ValueError(f"schedule {s.name!r} uses optimizer {s.optimizer!r}, not 'sgd'")
    return make_recipe(lr0=s.learning_rate, final_lr_fraction=s.final_lr_fraction, momentum=s.momentum,
                       warmup_momentum=s.warmup_momentum, warmup_bias_lr=s.warmup_bias_lr,
                       warmup_epochs=s.warmup_epochs, min_warmup_iters=s.warmup_steps, epochs=s.epochs,
                       steps_per_epoch=max(total_steps // s.epochs, 1), batch_size=s.batch_size,
                       nominal_batch=s.nominal_batch, weight_decay=s.weight_decay, clip_norm=s.clip_norm)


DARKNET_BURN_IN_POWER = 4  # src/network.c get_current_rate: rate * pow(batch / burn_in, power), power 4


def learning_rate(s: Schedule, total_steps: int) -> optax.Schedule:
    """Linear warm-up (darknet: burn-in (step / warmup)^4), then piecewise-constant decay at the
    given fractions of training. For an sgd schedule: the decayed weights' lr per batch
    (sgd_recipe.learning_rates has every group's)."""
    if s.optimizer == "sgd":
        recipe = recipe_for(s, total_steps)
        return lambda step: learning_rates(recipe, step)["weight"]
    if s.optimizer == "darknet":
        burn_in = max(s.warmup_steps, 1)

        def warmup(step):
            return s.learning_rate * (jnp.minimum(step, burn_in) / burn_in) ** DARKNET_BURN_IN_POWER
    else:
        warmup = optax.linear_schedule(s.learning_rate / 100, s.learning_rate, max(s.warmup_steps, 1))
    boundaries = {max(int(f * total_steps) - s.warmup_steps, 1): s.decay_factor for f in s.decay_at}
    constant = optax.piecewise_constant_schedule(s.learning_rate, boundaries)
    return optax.join_schedules([warmup, constant], [s.warmup_steps])


def conv_kernels(params) -> dict:
    """True for the leaves darknet decays: conv kernels (named 'kernel', 2 or more axes)."""
    return jax.tree_util.tree_map_with_path(
        lambda path, leaf: getattr(path[-1], "key", None) == "kernel" and leaf.ndim >= 2, params)


def optimizer(s: Schedule, total_steps: int) -> optax.GradientTransformation:
    """The schedule's optimizer, called once per batch (sgd accumulates batches inside)."""
    if s.optimizer == "sgd":
        return ultralytics_sgd(recipe_for(s, total_steps))
    if s.optimizer == "darknet":  # coupled decay on the kernels, then heavy-ball momentum; no clipping
        return optax.chain(optax.add_decayed_weights(s.weight_decay, mask=conv_kernels),
                           optax.sgd(learning_rate(s, total_steps), momentum=s.momentum))
    return optax.chain(
        optax.clip_by_global_norm(s.clip_norm),
        optax.adamw(learning_rate(s, total_steps), b1=s.b1, weight_decay=s.weight_decay),
    )

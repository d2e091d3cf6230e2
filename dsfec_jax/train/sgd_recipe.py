"""The ultralytics training recipe (YOLO-on-RD family) as one optax transformation: SGD with Nesterov
momentum over three parameter groups, a warm-up of learning rate, momentum and accumulation, a linear
per-epoch decay, gradient accumulation to a nominal batch of 64 and gradient clipping.

Facts, read (not copied) from ultralytics/ultralytics. We follow the 8.3 trainer (commit 3c5ac618,
the YOLOv8/YOLO11 line; ultralytics/engine/trainer.py: _setup_train, _do_train, optimizer_step,
build_optimizer) with the defaults of ultralytics/cfg/default.yaml:

- torch.optim.SGD(lr0 0.01, momentum 0.937, nesterov=True), coupled (L2) weight decay 5e-4:
  g += wd * p; buf = m * buf + g (buf = g on the first step); p -= lr * (g + m * buf);
- groups: conv/linear weights (decayed), normalisation weights (no decay), biases (no decay);
- lf(epoch) = max(1 - epoch / epochs, 0) * (1 - lrf) + lrf, lrf 0.01, set once per epoch (LambdaLR);
- warm-up over nw = max(round(warmup_epochs * batches per epoch), 100) batches (warmup_epochs 3),
  applied while batch index ni <= nw (np.interp over [0, nw]): the bias group's lr falls from
  warmup_bias_lr 0.1 to lr0 * lf(epoch), the other groups' rise from 0 to it; momentum rises from
  warmup_momentum 0.8 to 0.937; accumulate = max(1, round(interp(ni, [0, nw], [1, nbs / batch])));
  warmup_epochs 0 turns the warm-up off;
- accumulate = max(round(nbs / batch), 1) with nbs 64: the optimizer steps on batch ni when
  ni - (batch of the last step) >= accumulate (the first batch is ni 0, "no step yet" is -1), on the
  SUM of the gradients since the last step (loss.backward() adds into .grad); our loss is already
  multiplied by the batch size, as ultralytics' is (models/yolo_rd/loss.py);
- weight decay is scaled by batch * accumulate / nbs;
- before each step the summed gradients are clipped to global norm 10 (clip_grad_norm_:
  scale by min(10 / (norm + 1e-6), 1)), before weight decay is added.
Later ultralytics (the YOLO26 line, e.g. commit 00016300) drops the 100-batch floor, caps the warm-up
at epochs - 1 and ends it at ni < nw; we keep the 8.3 rules, the line that trains YOLOv8 (the paper
names no ultralytics version).

Gradient accumulation: done exactly as ultralytics does it, inside the optimizer. Every train step
is one batch (so the loop's step counter, checkpoints, resume and `--steps` keep their meaning);
the optimizer state holds the running gradient sum, the batch counter ni and the batch of the last
step, and emits zero updates on the batches where ultralytics would not step. We did not use
optax.MultiSteps: it averages instead of summing (the clip threshold and lr are tuned for the sum of
batch-scaled losses), its every-k schedule counts optimizer steps rather than batches (the warm-up
ramps accumulate per batch), and its inner schedule would see optimizer steps, not ni. Dropping
accumulation is not equivalent either: at batch 16 it would take 4x as many steps, each on a
quarter-size gradient sum, with a different momentum horizon and decay. The price is one extra
params-sized buffer in the optimizer state.

Our deviations, as choices:
- Flax trees have no module types, so groups come from leaf names and ranks: a leaf whose name
  contains "bias" is a bias (ultralytics tests the full name the same way); a leaf named "*kernel*"
  or of rank >= 2 (conv and dense weights) is decayed; the rest (BatchNorm/LayerNorm "scale", rank
  1) is not. The Adapter's scalar gates "gamma", "alpha" and "fusion_weight" (no ultralytics
  counterpart) fall in the no-decay group like BN weights: they set a scale, not a filter, and
  decay would pull the gates back towards their zero start.
- ultralytics evaluates and ships an EMA of the weights (ModelEMA); that is the train step's
  business, not the optimizer's, and is not done here.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

GROUPS = ("weight", "no_decay", "bias")  # ultralytics' g[0] (decayed), g[1] (BN weights), g[2] (biases)
CLIP_EPS = 1e-6  # torch.nn.utils.clip_grad_norm_ divides by norm + 1e-6


@dataclasses.dataclass(frozen=True)
class SGDRecipe:
    """Every number the recipe needs, derived from a schedule and the run's length (recipe_for)."""
    lr0: float
    final_lr_fraction: float   # lrf
    momentum: float
    warmup_momentum: float
    warmup_bias_lr: float
    epochs: int
    steps_per_epoch: int       # batches per epoch (ultralytics' nb)
    warmup_iters: int          # nw; -1: no warm-up
    accumulate: int            # batches summed per optimizer step after the warm-up
    nominal_ratio: float       # nbs / batch: where the warm-up's accumulate ramp ends
    weight_decay: float        # already scaled by batch * accumulate / nbs
    clip_norm: float


def make_recipe(*, lr0: float, final_lr_fraction: float, momentum: float, warmup_momentum: float,
                warmup_bias_lr: float, warmup_epochs: float, min_warmup_iters: int, epochs: int,
                steps_per_epoch: int, batch_size: int, nominal_batch: int, weight_decay: float,
                clip_norm: float) -> SGDRecipe:
    """The recipe with ultralytics' derived numbers: warm-up length, accumulate, scaled decay."""
    for name, value in (("epochs", epochs), ("steps_per_epoch", steps_per_epoch), ("batch_size", batch_size),
                        ("nominal_batch", nominal_batch)):
        if not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"sgd recipe: {name} must be a positive integer, got {value!r}")
    if warmup_epochs < 0 or min_warmup_iters < 0:
        raise ValueError(f"sgd recipe: warmup_epochs and warmup_steps must be >= 0, got "
                         f"{warmup_epochs!r} and {min_warmup_iters!r}")
    warmup_iters = max(round(warmup_epochs * steps_per_epoch), min_warmup_iters) if warmup_epochs > 0 else -1
    accumulate = max(round(nominal_batch / batch_size), 1)
    return SGDRecipe(lr0=lr0, final_lr_fraction=final_lr_fraction, momentum=momentum,
                     warmup_momentum=warmup_momentum, warmup_bias_lr=warmup_bias_lr, epochs=epochs,
                     steps_per_epoch=steps_per_epoch, warmup_iters=warmup_iters, accumulate=accumulate,
                     nominal_ratio=nominal_batch / batch_size,
                     weight_decay=weight_decay * batch_size * accumulate / nominal_batch, clip_norm=clip_norm)


def lr_factor(r: SGDRecipe, epoch):
    """ultralytics' linear lf(epoch): 1 at epoch 0, lrf at the end (and after)."""
    return jnp.maximum(1.0 - epoch / r.epochs, 0.0) * (1.0 - r.final_lr_fraction) + r.final_lr_fraction


def warmup_fraction(r: SGDRecipe, step):
    """Where batch `step` (ni) lies in the warm-up: 0 at its start, 1 at its end and after."""
    if r.warmup_iters <= 0:  # no warm-up (np.interp over [0, 0] also gives the end value)
        return jnp.ones_like(jnp.asarray(step, jnp.float32))
    return jnp.clip(jnp.asarray(step, jnp.float32) / r.warmup_iters, 0.0, 1.0)


def learning_rates(r: SGDRecipe, step) -> dict:
    """{group: learning rate} used by the optimizer step taken on batch `step` (ni, from 0)."""
    target = r.lr0 * lr_factor(r, jnp.asarray(step) // r.steps_per_epoch)
    t = warmup_fraction(r, step)
    starts = dict(zip(GROUPS, (0.0, 0.0, r.warmup_bias_lr)))
    return {group: start + t * (target - start) for group, start in starts.items()}


def momentum_at(r: SGDRecipe, step):
    """SGD momentum used on batch `step`: warm-up momentum rising to the recipe's."""
    return r.warmup_momentum + warmup_fraction(r, step) * (r.momentum - r.warmup_momentum)


def accumulation_table(r: SGDRecipe) -> np.ndarray:
    """accumulate for batches 0..nw (the last entry holds from then on), computed in float64 with
    np.interp and round-half-even exactly as ultralytics does: the ramp hits .5 ties, which float32
    on the device could round the other way. nw + 1 int32s (475 for yolo_paper on RADDet's size)."""
    if r.warmup_iters <= 0:
        return np.array([r.accumulate], np.int32)
    ni = np.arange(r.warmup_iters + 1)
    ramp = np.interp(ni, [0, r.warmup_iters], [1, r.nominal_ratio]).round().astype(np.int32)
    return np.maximum(ramp, 1)


def accumulate_at(r: SGDRecipe, step, table=None):
    """Batches summed per optimizer step, as in force on batch `step`."""
    table = jnp.asarray(accumulation_table(r) if table is None else table)
    return table[jnp.minimum(jnp.asarray(step), table.shape[0] - 1)]


def param_group(path, leaf) -> str:
    """The ultralytics group of one parameter leaf (see the module docstring for the rule)."""
    name = str(getattr(path[-1], "key", path[-1])) if path else ""
    if "bias" in name:
        return "bias"
    if "kernel" in name or np.ndim(leaf) >= 2:
        return "weight"
    return "no_decay"


def param_groups(params):
    """A tree like `params` holding each leaf's group name."""
    return jax.tree_util.tree_map_with_path(param_group, params)


class UltralyticsSGDState(NamedTuple):
    count: jnp.ndarray            # batches seen: ultralytics' ni for the next batch
    last_step: jnp.ndarray        # ni of the last optimizer step; -1 before the first
    accumulated: optax.Updates    # gradient sum since the last step
    momentum_buffer: optax.Updates


def _clip_coefficient(grads, max_norm: float):
    norm = optax.tree.norm(grads)
    return jnp.minimum(max_norm / (norm + CLIP_EPS), 1.0)


def nesterov_step(r: SGDRecipe, step, grads, params, buffers):
    """torch.optim.SGD(nesterov=True) on batch `step` with per-group lr and coupled weight decay:
    (updates, new momentum buffers)."""
    lrs, m = learning_rates(r, step), momentum_at(r, step)
    groups = param_groups(params)
    decayed = jax.tree.map(lambda grp, g, p: g + r.weight_decay * p if grp == "weight" else g, groups, grads, params)
    buffers = jax.tree.map(lambda g, buf: (m * buf + g).astype(buf.dtype), decayed, buffers)
    updates = jax.tree.map(lambda grp, g, buf: (-lrs[grp] * (g + m * buf)).astype(g.dtype), groups, decayed, buffers)
    return updates, buffers


def ultralytics_sgd(r: SGDRecipe) -> optax.GradientTransformation:
    """One call per batch: sums gradients and, on ultralytics' stepping batches, clips the sum and
    applies Nesterov SGD with the group's lr and weight decay (zero updates otherwise)."""
    table = accumulation_table(r)

    def init(params):
        zeros = lambda: jax.tree.map(jnp.zeros_like, params)  # two trees: the train step donates both
        return UltralyticsSGDState(jnp.zeros((), jnp.int32), -jnp.ones((), jnp.int32), zeros(), zeros())

    def update(grads, state, params=None):
        if params is None:
            raise ValueError("ultralytics_sgd needs params (weight decay and parameter groups)")
        ni = state.count
        summed = jax.tree.map(jnp.add, state.accumulated, grads)
        step_now = ni - state.last_step >= accumulate_at(r, ni, table)
        coefficient = _clip_coefficient(summed, r.clip_norm)  # on the sum, before weight decay
        clipped = jax.tree.map(lambda g: coefficient * g, summed)
        updates, buffers = nesterov_step(r, ni, clipped, params, state.momentum_buffer)
        updates = jax.tree.map(lambda u: jnp.where(step_now, u, jnp.zeros_like(u)), updates)
        buffers = jax.tree.map(lambda new, old: jnp.where(step_now, new, old), buffers, state.momentum_buffer)
        accumulated = jax.tree.map(lambda s: jnp.where(step_now, jnp.zeros_like(s), s), summed)
        last = jnp.where(step_now, ni, state.last_step)
        return updates, UltralyticsSGDState(ni + 1, last, accumulated, buffers)

    return optax.GradientTransformation(init, update)

"""Weight EMA as ultralytics trains (ultralytics/utils/torch_utils.py ModelEMA, 8.4.190): an
exponential moving average of the weights, validated and shipped in place of the raw ones.

ema = d * ema + (1 - d) * current, with d = 0.9999 * (1 - exp(-updates / 2000)) after `updates`
optimizer steps: the ramp lets the average follow the fast early weights and settle into a long
average later. ModelEMA averages every floating entry of the model's state_dict, so BatchNorm's
running statistics too, and updates once per optimizer step (trainer.optimizer_step), not per
batch: under ultralytics' gradient accumulation (train/sgd_recipe.py) the batches that only sum
gradients leave the average alone. The average starts as a copy of the initial weights
(a warm start's, if any).

The update runs inside the jitted train step (train/step.py calls `updated`); the state gains
an EMA_KEY entry, so checkpoints keep it and a resume continues the same average.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from ..core.averaged_weights import EMA_KEY, weights_of
from .sgd_recipe import UltralyticsSGDState

DECAY = 0.9999   # ModelEMA's decay: the ramp's limit
TAU = 2000.0     # ModelEMA's tau: after TAU updates the ramp is at 1 - 1/e of its height
AVERAGED = ("params", "batch_stats")


def decay(updates):
    """The decay after `updates` optimizer steps (counted from 1, as ModelEMA counts). -expm1(-x)
    is 1 - exp(-x) without float32's cancellation while the ramp is small (ModelEMA computes in
    float64)."""
    return -DECAY * jnp.expm1(-jnp.asarray(updates, jnp.float32) / TAU)


def resume_hint(differences: list) -> str:
    """A sentence for a resume refused over the average ((path, old, new) run.json differences):
    a run started before the schedule had `ema` trained without one and resumes only so."""
    if any(path == "schedule.ema." and old == "<absent>" for path, old, _ in differences):
        return " It was started before runs kept a weight EMA: resume it with --no-ema."
    return ""


def with_ema(state: dict, enabled: bool) -> dict:
    """`state` with a fresh average of its weights when `enabled` (a copy: the train step donates
    the state, and one buffer cannot be donated twice)."""
    if not enabled:
        return state
    copies = {k: jax.tree.map(jnp.copy, state[k]) for k in AVERAGED}
    return {**state, EMA_KEY: {**copies, "updates": jnp.zeros((), jnp.int32)}}


def optimizer_stepped(old_opt_state, new_opt_state):
    """Whether the optimizer stepped on this batch (a traced bool): an accumulating optimizer
    steps on some batches only (the ultralytics recipe, optax.MultiSteps); any other on each."""
    def accumulating(opt_state):
        kinds = (UltralyticsSGDState, optax.MultiStepsState)
        return [s for s in jax.tree.leaves(opt_state, is_leaf=lambda x: isinstance(x, kinds)) if isinstance(s, kinds)]

    found = accumulating(new_opt_state)
    if not found:
        return jnp.asarray(True)
    old, new = accumulating(old_opt_state)[0], found[0]
    if isinstance(new, UltralyticsSGDState):
        return new.last_step == old.count
    return new.mini_step == 0


def averaged(average: dict, current: dict, stepped) -> dict:
    """One ModelEMA.update of `average` ({params, batch_stats, updates}) towards `current`'s
    weights where `stepped`, else `average` unchanged. Integer leaves are not averaged."""
    updates = average["updates"] + jnp.asarray(stepped, jnp.int32)
    d = decay(updates)

    def blend(e, x):
        if not jnp.issubdtype(e.dtype, jnp.floating):
            return e
        return jnp.where(stepped, (d * e + (1.0 - d) * x).astype(e.dtype), e)

    return {**{k: jax.tree.map(blend, average[k], current[k]) for k in AVERAGED}, "updates": updates}


def updated(old_state: dict, new_state: dict) -> dict:
    """`new_state` (after a train step from `old_state`) with its average updated; a state without
    one is returned as it is."""
    if EMA_KEY not in old_state:
        return new_state
    stepped = optimizer_stepped(old_state["opt_state"], new_state["opt_state"])
    return {**new_state, EMA_KEY: averaged(old_state[EMA_KEY], new_state, stepped)}


def evaluated(state: dict) -> dict:
    """{'params', 'batch_stats'} a validation runs: the average's where the state keeps one."""
    weights = weights_of(state)
    return {k: weights[k] for k in AVERAGED}


def with_evaluated_batch_stats(state: dict, batch_stats) -> dict:
    """`state` with the evaluated weights' BN statistics replaced (train/precise_bn.py)."""
    if EMA_KEY in state:
        return {**state, EMA_KEY: {**state[EMA_KEY], "batch_stats": batch_stats}}
    return {**state, "batch_stats": batch_stats}

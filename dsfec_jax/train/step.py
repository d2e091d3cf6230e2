"""The train step: one jitted pure function (state, batch) -> (state, metrics), state donated.

state = {'params', 'batch_stats', 'opt_state', 'step'}, plus 'ema' for a run that averages its
weights (train/ema.py); batch = {'inputs': pillar tensors, 'targets': per-head target maps}.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from .. import zoo
from . import ema
from .warm_start import warm_start


def init_state(detector, tx: optax.GradientTransformation, rng: jax.Array,
               init_variables: dict | None = None) -> dict:
    """A fresh training state; `init_variables` (trained variables of this or a related network)
    replace the fresh ones module by module where they match (train.warm_start)."""
    variables = detector.init(rng)
    if init_variables is not None:
        variables = warm_start(variables, init_variables)[0]
    return {"params": variables["params"], "batch_stats": variables.get("batch_stats", {}),
            "opt_state": tx.init(variables["params"]), "step": jnp.zeros((), jnp.int32)}


def loss_function(detector):
    """(params, batch_stats, batch, extra={}) -> (loss, (parts, new batch_stats)) with the family's
    loss: what the train step differentiates (the training benchmark times it too). `extra`
    holds traced network inputs beside the batch's (the one-shot supernet's `depth`)."""
    compute_loss = zoo.family_of(detector.config).loss(detector.config)

    def loss_fn(params, batch_stats, batch, extra=None):
        variables = {"params": params, "batch_stats": batch_stats}
        outputs, updates = detector.apply(variables, {**batch["inputs"], **(extra or {})}, train=True)
        loss, parts = compute_loss(outputs, batch["targets"])
        return loss, (parts, updates["batch_stats"])

    return loss_fn


def train_step_fn(detector, tx: optax.GradientTransformation, extra_inputs: tuple[str, ...] = ()):
    """The un-jitted step (state, batch, *extra) -> (new state, {'loss', 'grad_norm', parts...}) with
    the family's loss. `extra_inputs` name traced network inputs passed after the batch (the
    one-shot supernet's `depth`), so one compiled step serves every value of them."""
    loss_fn = loss_function(detector)

    def train_step(state: dict, batch: dict, *extra_values):
        extra = dict(zip(extra_inputs, extra_values))
        grad_fn = jax.value_and_grad(loss_fn, has_aux=True)
        (loss, (parts, batch_stats)), grads = grad_fn(state["params"], state["batch_stats"], batch, extra)
        updates, opt_state = tx.update(grads, state["opt_state"], state["params"])
        new_state = {"params": optax.apply_updates(state["params"], updates), "batch_stats": batch_stats,
                     "opt_state": opt_state, "step": state["step"] + 1}
        new_state = ema.updated(state, new_state)  # the weight average, where the state keeps one
        metrics = {"loss": loss, "grad_norm": optax.tree.norm(grads), **parts}
        return new_state, metrics

    return train_step


def batch_on_device(batch: dict) -> dict:
    """`batch` with its 'inputs' and 'targets' copied into XLA buffers, the copies finished.
    The prefetch worker calls it, so the copy overlaps the running step. It also matters with
    async dispatch off (core/host_memory.py): XLA runs a call inline on the calling thread only
    when all of its inputs are ready. A numpy array that is not 64-byte aligned is copied
    asynchronously, and then the whole step would run on a pool thread, whose heap maps its
    temporary buffer afresh on every call."""
    moved = jax.device_put({"inputs": batch["inputs"], "targets": batch["targets"]})
    return {**batch, **jax.block_until_ready(moved)}


def make_train_step(detector, tx: optax.GradientTransformation):
    """The jitted step (state, batch) -> (state, metrics), state donated."""
    return jax.jit(train_step_fn(detector, tx), donate_argnums=0)


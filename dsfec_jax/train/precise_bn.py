"""Batch-norm running statistics re-estimated with the current weights ("precise BN": fvcore's
update_bn_stats, detectron2's PreciseBN hook), before a validation and the checkpoints after it.

Why: the running statistics follow the batches with momentum 0.99 (layers/conv.BN_MOMENTUM, also
darknet's rolling .99), so after s steps the initial (0, 1) statistics still weigh 0.99^s and the
early, very different weights' statistics most of the rest: 13 % after the camera quick profile's
200 steps, enough to ruin a short run's score (docs/camera.md, "Precise BN", has the measured
case). Over a 50k-step schedule the two agree; re-estimating costs a few forward passes.

The statistics of each batch are read from one train-mode forward with zeroed running statistics
(models/bn_statistics.py: exact, no cancellation) and averaged over the batches, as
update_bn_stats averages them. Only 'batch_stats' changes; a train-mode step never reads it, so
the training that follows is the same. A run with a weight EMA (train/ema.py) validates the
average, so the statistics are re-estimated for the average's parameters and replace its own.
"""

from __future__ import annotations

from typing import Callable, Sequence

import jax
import jax.numpy as jnp

from ..layers.conv import BN_MOMENTUM
from ..models.bn_statistics import batch_statistics
from .ema import evaluated, with_evaluated_batch_stats


def precise_bn(detector, batches: Callable[[], Sequence[dict]], momentum: float = BN_MOMENTUM) -> Callable[[dict], dict]:
    """fn(train state) -> the state with 'batch_stats' = the mean batch statistics of `batches()`
    (BatchStream-layout batches; made when first needed) under the state's parameters."""
    stats_of = batch_statistics(detector, momentum)
    made: list = []

    def apply(state: dict) -> dict:
        if not made:
            made.extend(batches())
        weights = evaluated(state)  # a weight average's own statistics, where the run keeps one
        per_batch = [stats_of(weights, b["inputs"]) for b in made]
        mean = jax.tree.map(lambda *s: jnp.mean(jnp.stack(s), 0), *per_batch)
        return with_evaluated_batch_stats(state, mean)

    return apply

"""Batch-norm statistics of a batch under given weights: one train-mode forward with zeroed running
statistics. Flax stores m * 0 + (1 - m) * batch when the running statistics start at zero, so
dividing by (1 - m) gives the batch's own mean and variance exactly (no cancellation).

What train/precise_bn.py averages over batches before a validation, and what the bench's stand-in
camera weights carry (modalities/image/bench.py): both read it here, deploy's doors not leading
to train.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..layers.conv import BN_MOMENTUM


def batch_statistics(detector, momentum: float = BN_MOMENTUM):
    """jitted fn(variables, inputs) -> 'batch_stats' holding the batch statistics of `inputs` under
    variables' params (variables' own 'batch_stats' give only the tree's shape)."""

    def stats(variables: dict, inputs) -> dict:
        zeros = jax.tree.map(jnp.zeros_like, variables["batch_stats"])
        new = detector.apply({"params": variables["params"], "batch_stats": zeros}, inputs, train=True)[1]
        return jax.tree.map(lambda s: s / (1 - momentum), new["batch_stats"])

    return jax.jit(stats)

"""Jitted batch-1 latency, whole network and per stage.

On a shared 2-core box another process can move a timing several-fold (docs/profiler.md, "Latency
on a shared box"), so models are timed in one interleaved loop (A B A B ...) and medians and ratios
are what to quote.
"""

from __future__ import annotations

import time
from typing import Callable

import jax
import numpy as np


def timing_variables(detector, seed: int = 0) -> dict:
    """Variables of `detector`'s shapes for a timing loop, made without compiling anything.

    CPU convolution time does not depend on the weights' values, so these need only be finite and
    of a realistic scale: weights ~ N(0, 1/fan_in), biases and BN shifts 0, BN scales and variances
    1. `detector.init` would give other values at the price of compiling the whole forward pass
    (seconds per model, twice per search candidate before this existed; docs/profiler.md, "Latency
    on a shared box")."""
    rng = np.random.default_rng(seed)

    def fill(path, leaf):
        name = getattr(path[-1], "key", "")
        if name in ("var", "scale"):
            return np.ones(leaf.shape, leaf.dtype)
        if name in ("mean", "bias") or len(leaf.shape) < 2:
            return np.zeros(leaf.shape, leaf.dtype)
        fan_in = int(np.prod(leaf.shape[:-1]))
        return (rng.standard_normal(leaf.shape) * fan_in**-0.5).astype(leaf.dtype)

    shapes = jax.eval_shape(detector.init, jax.random.key(seed))
    # on the device, as a predictor holds them: numpy weights would be converted again on every
    # timed call, which the predictors no longer pay
    return jax.device_put(jax.tree_util.tree_map_with_path(fill, shapes))


def stage_functions(detector, variables, inputs, stages: Callable[..., dict] | None = None) -> dict:
    """name -> zero-argument callable that runs that stage (jitted, compiled, blocking): 'total',
    the whole network, and with `stages` (the modality's `latency_stages(detector, variables,
    inputs)` -> {stage: jitted callable}) each of its stages."""
    full = jax.jit(detector.apply)
    calls = {"total": lambda: full(variables, inputs)}
    if stages is not None:
        calls.update(stages(detector, variables, inputs))
    return {k: (lambda f=f: jax.block_until_ready(f())) for k, f in calls.items()}


def time_interleaved(suites: dict[str, dict], repeats: int = 20, warmup: int = 3) -> dict:
    """suites: model -> {stage: callable}. Returns model -> stage -> {median_ms, p10_ms, p90_ms}
    (the spread over the repeats)."""
    for fns in suites.values():
        for fn in fns.values():
            for _ in range(warmup):
                fn()
    samples = {m: {s: [] for s in fns} for m, fns in suites.items()}
    for _ in range(repeats):
        for model, fns in suites.items():
            for stage, fn in fns.items():
                t0 = time.perf_counter()
                fn()
                samples[model][stage].append(1e3 * (time.perf_counter() - t0))
    return {m: {s: dict(zip(("p10_ms", "median_ms", "p90_ms"), map(float, np.percentile(v, [10, 50, 90]))))
                for s, v in st.items()} for m, st in samples.items()}

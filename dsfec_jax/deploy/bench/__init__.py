"""Batch-1 latency from raw input (points, a range-Doppler map, or a camera image) to boxes, per stage
and runtime (`dsfec bench`).

One job per module, none of them modality-specific: `model_setup` (shipped or initial variables),
`stages` (the runtimes, an export cached per worker, JAX throughput by batch), `timing` (the
interleaved loop that times every chain), `workers` (one pinned worker process per thread count,
and `run`, which launches them), `report` (table, ratios, plot). Each modality builds its own chains
(`Modality.bench_chains`, modalities/<m>/bench.py). `python -m dsfec_jax.deploy.bench` is the worker
entry point (`__main__`: it looks the modalities up).
"""

from .model_setup import bench_variables
from .report import markdown, plot, ratios
from .stages import JAX_BATCHES, RUNTIMES, cached_export, jax_throughput
from .timing import time_chains
from .workers import run, worker

__all__ = ["JAX_BATCHES", "RUNTIMES", "bench_variables", "cached_export", "jax_throughput", "markdown", "plot",
           "ratios", "run", "time_chains", "worker"]

"""Batch-1 latency from raw points to boxes, per stage and runtime (`dsfec bench`).

One job per module: `model_setup` (detector, variables, frame, Predictor), `stages` (each runtime's
network and decode calls, JAX throughput by batch), `timing` (the chain of four stages and the
interleaved loop that times every chain), `workers` (one pinned worker process per thread count,
and `run`, which launches them), `report` (table, ratios, plot). `python -m dsfec_jax.deploy.bench`
is the worker entry point (`__main__`).
"""

from .report import markdown, plot, ratios
from .model_setup import model_setup
from .stages import JAX_BATCHES, RUNTIMES, jax_stages, jax_throughput, onnx_graphs, ort_stages
from .timing import STAGES, chain, time_chains
from .workers import main, run, worker

__all__ = ["JAX_BATCHES", "RUNTIMES", "STAGES", "chain", "jax_stages", "jax_throughput", "main", "markdown",
           "model_setup", "onnx_graphs", "ort_stages", "plot", "ratios", "run", "time_chains", "worker"]

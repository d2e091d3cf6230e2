"""Batch-1 latency from raw input (points, a range-Doppler map, or a camera image) to boxes, per stage
and runtime (`dsfec bench`).

One job per module: `model_setup` (detector, variables, frame, RD sample or street image, Predictor),
`stages` (each runtime's network and decode calls for a point model, JAX throughput by batch),
`stages_rd` (each runtime's network + decode and NMS calls for an RD model), `stages_camera` (each
runtime's CameraPipeline for a camera model), `timing` (the chains of stages and
the interleaved loop that times every chain), `workers` (one pinned worker process per thread count,
and `run`, which launches them), `report` (table, ratios, plot). `python -m dsfec_jax.deploy.bench`
is the worker entry point (`__main__`).
"""

from .report import markdown, plot, ratios
from .model_setup import camera_model_setup, model_setup, rd_model_setup
from .stages import JAX_BATCHES, RUNTIMES, jax_stages, jax_throughput, onnx_graphs, ort_stages
from ...modalities.image.bench import camera_onnx_graph, camera_pipeline
from ...modalities.rd.bench import rd_jax_stages, rd_onnx_graph, rd_ort_stages
from .timing import CAMERA_STAGES, RD_STAGES, STAGES, camera_chain, chain, rd_chain, time_chains
from .workers import camera_chains, main, run, worker

__all__ = ["CAMERA_STAGES", "JAX_BATCHES", "RD_STAGES", "RUNTIMES", "STAGES", "camera_chain", "camera_chains",
           "camera_model_setup", "camera_onnx_graph", "camera_pipeline", "chain", "jax_stages", "jax_throughput",
           "main", "markdown", "model_setup", "onnx_graphs", "ort_stages", "plot", "ratios", "rd_chain",
           "rd_jax_stages", "rd_model_setup", "rd_onnx_graph", "rd_ort_stages", "run", "time_chains", "worker"]

"""What every modality's benchmark stages share: the runtimes (jax, onnx, onnx-int8), an export
written once per worker and shared by its runtimes (`cached_export`), and JAX's throughput of
network + decode at batch sizes above 1, which the batch-1 chains do not show (`jax_throughput`).
Each modality's stages are its own (modalities/<m>/bench.py).
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import numpy as np

RUNTIMES = ("jax", "onnx", "onnx-int8")
JAX_BATCHES = (1, 2, 4, 8)


def cached_export(workdir: Path, tag: str, export, quantize, int8: bool) -> Path:
    """WORKDIR/TAG (written once per worker by `export(dir)`), or its INT8 copy WORKDIR/TAG_int8
    (`quantize(fp32_dir, int8_dir)`): one worker's runtimes share the files."""
    fp32 = workdir / tag
    if not (fp32 / "model.onnx").exists():
        export(fp32)
    if not int8:
        return fp32
    int8_dir = workdir / f"{tag}_int8"
    if not (int8_dir / "model.onnx").exists():
        quantize(fp32, int8_dir)
    return int8_dir


def jax_throughput(det, variables, fn, repeats: int, hw: tuple[int, int] | None = None) -> dict:
    """Frames/s of the jitted fn(variables, inputs) (network + decode; + NMS for an RD model, whose
    predictor compiles it) at each batch size (batch 1 .. 8) -> {batch: fps}. `hw`: the input size of
    the models whose dummy inputs take one (camera images: the bench's letterboxed size)."""
    out = {}
    for b in JAX_BATCHES:
        x = det.dummy_inputs(b, occupancy=0.25) if hw is None else det.config.dummy_inputs(b, hw=tuple(hw))
        jax.block_until_ready(fn(variables, x))
        times = []
        for _ in range(max(3, repeats // b)):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(variables, x))
            times.append(time.perf_counter() - t0)
        out[str(b)] = round(b / float(np.median(times)), 2)
    return out

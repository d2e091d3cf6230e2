"""What every modality's benchmark stages share: the runtimes (jax, onnx, onnx-int8), an export
written once per worker and shared by its runtimes (`cached_export`), and JAX's throughput of
network + decode at batch sizes above 1, which the batch-1 chains do not show (`jax_throughput`).
Each modality's stages are its predictors' own (`stages(items)`, modalities/stages.py; the chains:
modalities/<m>/bench.py).
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import numpy as np

from ...core import progress

RUNTIMES = ("jax", "onnx", "onnx-int8")
JAX_BATCHES = (1, 2, 4, 8)
NO_HEARTBEAT_S = 3600.0


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
    """Frames/s of the jitted fn(variables, inputs) (the JAX predictor's network + decode) at each batch size (batch 1 .. 8) -> the record fields 'throughput_fps'
    ({batch: fps at the median time}) and 'throughput_fps_p10_p90' ({batch: [fps at the 90th
    percentile time, at the 10th]}: the spread over the repeats). `hw`: the input size of the
    models whose dummy inputs take one (camera images: the bench's letterboxed size)."""
    fps, spread = {}, {}
    # start and end lines only: the worker's enclosing "preparing <model>" stage already beats
    with progress.stage(f"measuring {det.name}'s JAX throughput at batch {', '.join(map(str, JAX_BATCHES))} "
                        "(each batch size compiles once)", heartbeat_s=NO_HEARTBEAT_S):
        for b in JAX_BATCHES:
            x = det.dummy_inputs(b, occupancy=0.25) if hw is None else det.config.dummy_inputs(b, hw=tuple(hw))
            jax.block_until_ready(fn(variables, x))
            times = []
            for _ in range(max(3, repeats // b)):
                t0 = time.perf_counter()
                jax.block_until_ready(fn(variables, x))
                times.append(time.perf_counter() - t0)
            p10, med, p90 = np.percentile(times, [10, 50, 90])
            fps[str(b)] = round(b / float(med), 2)
            spread[str(b)] = [round(b / float(p90), 2), round(b / float(p10), 2)]
    return {"throughput_fps": fps, "throughput_fps_p10_p90": spread}

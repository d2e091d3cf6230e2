"""The benchmark chains of a range-Doppler model (YOLO-RD; `dsfec bench`): each runtime's chain IS
its predictor's path, `RDPipeline.stages` (modalities/rd/predict.py, STAGES): representation (host
numpy: the heat / gray maps fitted to the input size, as the predictor makes them), network_decode
(network and DFL decode), nms (the host post-processing both predictors run: class-aware NMS, or
YOLOv10's top-k; models/yolo_rd/decode_host), to_map (boxes back to map pixels, class names).

jax: RDPredictor (its jitted network and decode, host NMS: its default). onnx / onnx-int8:
OrtRDPredictor over the export's graph (network + decode; int8 quantizes the network only,
calibrated on synthetic train RD samples) with intra_op_num_threads = the worker's thread count.

Without shipped weights the detector's initial variables load the host NMS about as trained weights
do: its class biases start at ultralytics' prior (sigmoid ~1e-4 at stride 8), and 96 of yolov8n's
2016 candidates pass conf 0.001 at 256 x 64 (a briefly trained yolov8n: a median 60).
"""

from __future__ import annotations

from pathlib import Path

from ...deploy.bench.model_setup import bench_variables
from ...deploy.bench.stages import cached_export, jax_throughput
from .predict import STAGES

__all__ = ["STAGES", "rd_chains"]

CALIBRATION_SAMPLES = 32  # synthetic train RD samples, seed 0, as the point bench's 32 frames


def rd_onnx_graph(det, variables, workdir: Path, int8: bool, input_hw) -> Path:
    """The export's directory (written once per worker), or its INT8 copy."""
    from ...data.rd.sources import load_rd_samples
    from .export import export_rd
    from .quantize import quantize_rd

    return cached_export(workdir, f"{det.name}_rd",
                         lambda out: export_rd(det, variables, out, input_hw=tuple(input_hw), jax_export=False),
                         lambda fp32, out: quantize_rd(fp32, out, load_rd_samples("synthetic", "train",
                                                                                   CALIBRATION_SAMPLES, seed=0)),
                         int8)


def rd_model_setup(name: str):
    """An RD model: (detector, variables, weights label, one synthetic test RD sample)."""
    from ... import zoo
    from ...data.rd.sources import load_rd_samples

    det = zoo.create(name)
    variables, label = bench_variables(det, name)
    return det, variables, label, load_rd_samples("synthetic", "test", 1, seed=0)[0]


def rd_predictor(det, variables, runtime: str, workdir: Path, threads: int, input_hw):
    """The RDPipeline of one runtime: RDPredictor (jax) or OrtRDPredictor (onnx, onnx-int8)."""
    from .ort import OrtRDPredictor
    from .predict import RDPredictor

    if runtime == "jax":
        return RDPredictor(det, variables, constant_weights=True)
    return OrtRDPredictor(rd_onnx_graph(det, variables, workdir, runtime == "onnx-int8", input_hw), threads=threads)


def rd_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int) -> dict:
    """runtime -> (chain of a range-Doppler model, record fields): the predictor's stages on the native
    map, padded as training pads it (data/rd representations, fit 'pad'), in one fixed-size graph."""
    from ...data.rd.representations import RDRepresentation, fitted_shape

    det, variables, label, sample = rd_model_setup(name)
    input_hw = fitted_shape(sample.shape, RDRepresentation())
    out, predictors = {}, {}
    for rt in runtimes:
        predictors[rt] = rd_predictor(det, variables, rt, workdir, threads, input_hw)
        out[rt] = (predictors[rt].stages([sample]), {"weights": label, "input_hw": list(input_hw)})
    if "jax" in out:  # the predictor's own jitted network and decode at batch 1 .. 8
        out["jax"][1].update(jax_throughput(det, predictors["jax"].variables, predictors["jax"].network, repeats))
    return out

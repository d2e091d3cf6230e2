"""The benchmark chains of a range-Doppler model (YOLO-RD; `dsfec bench`): representation (host
numpy: the heat / gray maps fitted to the input size), network_decode (network and DFL decode), nms
(class-aware NMS, or YOLOv10's top-k).

jax: the network and DFL decode jitted (modalities/rd/export.decoded_network), then the compiled post-processing
the JAX predictor runs (class-aware NMS, boxes/nms2d.detect_jax; YOLOv10's top-k) as a second jit.
onnx / onnx-int8: the export's graph (network + decode; int8 quantizes the network only, calibrated
on synthetic train RD samples) in ONNX Runtime with intra_op_num_threads = the worker's thread
count, then the host post-processing of OrtRDPredictor (models/yolo_rd/decode_host.host_detections).

Without shipped weights the detector's initial variables load the host NMS about as trained weights
do: its class biases start at ultralytics' prior (sigmoid ~1e-4 at stride 8), and 96 of yolov8n's
2016 candidates pass conf 0.001 at 256 x 64 (a briefly trained yolov8n: a median 60).
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax

from ...deploy.bench.model_setup import bench_variables
from ...deploy.bench.stages import cached_export, jax_throughput

STAGES = ("representation", "network_decode", "nms")
CALIBRATION_SAMPLES = 32  # synthetic train RD samples, seed 0, as the point bench's 32 frames


@functools.cache
def compiled_postprocess(kind: str):
    """jit(vmap(one image's post-processing)) at the evaluation settings: what decode.detect and
    decode_v10.detect_nms_free run after their decode."""
    from ...boxes.nms2d import detect_jax
    from ...models.yolo_rd.decode import EVAL_CONF, EVAL_IOU, EVAL_MAX_DET
    from ...models.yolo_rd.decode_v10 import top_detections
    from ...models.yolo_rd.decode_host import TOP_K

    if kind == TOP_K:
        def one(boxes, scores):
            return top_detections(boxes, scores, EVAL_CONF, EVAL_MAX_DET)
    else:
        def one(boxes, scores):
            return detect_jax(boxes, scores, EVAL_IOU, EVAL_CONF, max_detections=EVAL_MAX_DET, multi_label=True)
    return jax.jit(jax.vmap(one))


def rd_jax_stages(det, variables, input_hw) -> dict:
    from .export import decoded_network, input_specs, postprocess_kind

    names = det.config.input_names
    net = jax.jit(lambda v, *maps: decoded_network(det, v)(*maps))
    post = compiled_postprocess(postprocess_kind(det, variables, input_specs(det.config, input_hw, 1)))
    return {"network_decode": lambda inputs: jax.block_until_ready(net(variables, *(inputs[k] for k in names))),
            "nms": lambda out: jax.device_get(post(*out))}


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


def rd_ort_stages(export_dir: Path, threads: int) -> dict:
    from .ort import OrtRDPredictor

    predictor = OrtRDPredictor(export_dir, threads=threads)
    return {"network_decode": predictor.decoded, "nms": lambda out: predictor.postprocess(*out)}


def rd_model_setup(name: str):
    """An RD model: (detector, variables, weights label, one synthetic test RD sample)."""
    from ... import zoo
    from ...data.rd.sources import load_rd_samples

    det = zoo.create(name)
    variables, label = bench_variables(det, name)
    return det, variables, label, load_rd_samples("synthetic", "test", 1, seed=0)[0]


def rd_chain(sample, representation, input_names, stages: dict) -> list:
    """[(stage, fn(previous output) -> output)] from an RD sample to padded detections."""
    from ...data.rd.representations import representations

    def represent(_):
        maps = representations(sample, representation)
        return {k: maps[k][None] for k in input_names}

    return [("representation", represent), ("network_decode", stages["network_decode"]), ("nms", stages["nms"])]


def rd_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int) -> dict:
    """runtime -> (chain of a range-Doppler model, record fields): the native map, padded as training
    pads it (data/rd representations, fit 'pad'), in one fixed-size graph."""
    from ...data.rd.representations import RDRepresentation, fitted_shape
    from .predict import detecting_network

    det, variables, label, sample = rd_model_setup(name)
    representation = RDRepresentation()
    input_hw = fitted_shape(sample.shape, representation)
    out = {}
    for rt in runtimes:
        if rt == "jax":
            stages = rd_jax_stages(det, variables, input_hw)
        else:
            stages = rd_ort_stages(rd_onnx_graph(det, variables, workdir, rt == "onnx-int8", input_hw), threads)
        out[rt] = (rd_chain(sample, representation, det.config.input_names, stages),
                   {"weights": label, "input_hw": list(input_hw)})
    if "jax" in out:
        out["jax"][1].update(jax_throughput(det, variables, jax.jit(detecting_network(det)), repeats))
    return out

"""The network + decode and NMS stages of each runtime for a range-Doppler model (YOLO-RD).

jax: the network and DFL decode jitted (export_rd.decoded_network), then the compiled post-processing
the JAX predictor runs (class-aware NMS, boxes/nms2d.detect_jax; YOLOv10's top-k) as a second jit.
onnx / onnx-int8: the export's graph (network + decode; int8 quantizes the network only, calibrated
on synthetic train RD samples) in ONNX Runtime with intra_op_num_threads = the worker's thread
count, then the host post-processing of OrtRDPredictor (models/yolo_rd/decode_host.host_detections).
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax

from ...deploy.bench.stages import cached_export

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

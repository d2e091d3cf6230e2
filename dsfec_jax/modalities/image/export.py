"""Export one camera detector (Shuffle-YOLOv3, Darknet53-YOLOv3) to DIR: `model.onnx` (jax2onnx),
optionally `model.jax_export`, and `deploy.json`, with export.write_export as every family.

The graph is network -> YOLOv3 decode (models/camera/decode.decode, what CameraPredictor jits):
input `image` (B, H, W, 3) float32 in [0, 1], the letterboxed image at one fixed size; outputs
`boxes` (B, A, 4) xyxy in input (letterboxed) pixels and `scores` (B, A, C) = sigmoid(objectness)
x sigmoid(class), every anchor of the three scales in decode's order (A = 3 (HW/64 + HW/256 +
HW/1024): 6,552 at 256 x 416). The letterbox and darknet's post-processing (score > 0.005, per-class
NMS at IoU 0.45 over the multi-label (anchor, class) candidates, the 300 best; decode.detections)
stay on the host: modalities/image/ort.OrtCameraPredictor runs modalities/image/predict.CameraPipeline
around the graph.

Why NMS stays on the host (as for the RD family, modalities/rd/export.py): the JAX predictor runs
this NMS on the host too (boxes/nms2d.detect_host), so both runtimes share its code and its kept
boxes; a compiled NMS (boxes/nms2d.nms_jax, one greedy pass in a `fori_loop`) becomes an ONNX Loop over
every candidate, many times slower in ONNX Runtime than on the host for YOLO-RD's 2,016
candidates (docs/range-doppler.md, "Deploy"), and a camera graph has 32,760 at 256 x 416 with 5
classes; jax2onnx has no batching rule for that Loop either, so the graph would be batch 1 only.

The network is exported in the operators ONNX has (export.grouped: the depthwise kernels as one
grouped `Conv(group=C)`, the 1x1 convolutions as Conv with constant weights, which int8 quantizes);
jitted JAX keeps its fast kernels; the same weights serve both.

The input size is part of the graph. deploy.json records it with the letterbox rule that feeds it:
`letterbox.size` (the long side) and `letterbox.rect`. A rectangular graph (416 x 256 for the
street benchmark's 16:9 frames, the default) takes the images whose own rectangle
(data/camera/letterbox.network_shape, what CameraPredictor picks) it is; a square graph letterboxes
every image into the square, as darknet evaluates (CameraPredictor(rect=False)).
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from ...boxes.nms2d import MAX_NMS
from ...core.provenance import jsonable
from ...data.camera.letterbox import FILL, STRIDE, network_shape
from ...models.camera.config import INPUT
from ...models.camera.decode import EVAL_SCORE, MAX_DETECTIONS, NMS_IOU
from .predict import decoding_network
from ...deploy.export import grouped, write_export

OUTPUTS = ("boxes", "scores")  # per anchor: xyxy input pixels, sigmoid(obj) x sigmoid(cls) per class
DEFAULT_SIZE = 416  # the paper's input size: street frames go into 256 x 416


def street_input_hw(size: int = DEFAULT_SIZE) -> tuple[int, int]:
    """(H, W) the street benchmark's frames (16:9, 416 x 234 as rendered) are letterboxed into at long
    side `size`: 256 x 416 at 416."""
    from ...data.camera.sources import street_config

    camera = street_config().camera_model()
    return network_shape(size, camera.height / camera.width)


def check_input_hw(input_hw) -> tuple[int, int]:
    """(H, W) as ints, or a ValueError naming the field when a side is not a positive multiple of 32."""
    hw = tuple(int(v) for v in input_hw)
    if len(hw) != 2 or min(hw) < STRIDE or any(v % STRIDE for v in hw):
        raise ValueError(f"input_hw {tuple(input_hw)}: expected (H, W), positive multiples of {STRIDE} "
                         "(the networks' largest stride)")
    return hw


def letterbox_rule(input_hw) -> dict:
    """What deploy.json says about feeding the graph: the letterbox's long side and whether each
    image keeps its own rectangle (a rectangular graph) or goes into the square."""
    h, w = input_hw
    return {"size": max(h, w), "rect": h != w, "fill": FILL,
            "rule": "darknet letterbox: scaled by one factor until the long side fills the input, centred, "
                    "grey (fill) around; rect: each image's own rectangle (long side `size`, short side rounded "
                    "up to 32), which must be input_hw; else the size x size square"}


def baked_network(detector, variables):
    """fn(image (B, H, W, 3)) -> (boxes, scores): the network and the YOLOv3 decode with the weights
    baked in (what model.onnx holds)."""
    network = decoding_network(detector)
    return lambda image: network(variables, image)


def export_camera(detector, variables, out_dir: str | Path, source: dict | None = None,
                  input_hw: tuple[int, int] | None = None, batch_size: int = 1,
                  jax_export: bool = True) -> dict[str, Path]:
    """Write model.onnx, deploy.json and (with `jax_export`) model.jax_export to out_dir -> {name: path}.
    input_hw: the letterboxed (H, W) the graph takes (default: the street frames' 256 x 416)."""
    from ... import zoo
    from ..checks import require_modality

    require_modality(detector.config, "image", "export_camera")
    hw = check_input_hw(input_hw or street_input_hw())
    # the inference form (BatchNorm folded into the convs), every conv kept a Conv node
    detector, variables = zoo.deploy(detector, variables, for_export=True)
    det = grouped(detector)
    cfg = det.config
    specs = [jax.ShapeDtypeStruct((batch_size, *hw, 3), np.float32)]
    fields = {"model": cfg.name, "modality": "image", "config": jsonable(cfg), "batch_size": batch_size,
              "input_hw": list(hw), "classes": list(cfg.classes), "letterbox": letterbox_rule(hw),
              "postprocess": {"where": "host", "multi_label": True, "score_threshold": EVAL_SCORE,
                              "iou_threshold": NMS_IOU, "max_detections": MAX_DETECTIONS, "pre_top_k": MAX_NMS}}
    return write_export(baked_network(det, variables), specs, (INPUT,), OUTPUTS, out_dir, cfg.name, fields, source,
                        jax_export)

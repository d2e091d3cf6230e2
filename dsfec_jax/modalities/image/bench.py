"""The benchmark chains of a camera model (Shuffle-YOLOv3, Darknet53-YOLOv3; `dsfec bench`):
letterbox (host: the image scaled and centred into the network input), network_decode (network
and YOLOv3 decode), nms (darknet's host post-processing and the boxes mapped back to the image).

The network + decode stage of each runtime is run through the pipelines that also letterbox and
post-process (modalities/image/predict.CameraPipeline), so every
runtime's chain shares the host stages and differs by the network alone.

jax: CameraPredictor (the jitted network and YOLOv3 decode). onnx / onnx-int8: the export's graph
(export_camera: network + decode; int8 quantizes the convolutions only, calibrated on letterboxed
street train images) in ONNX Runtime with intra_op_num_threads = the worker's thread count, through
OrtCameraPredictor. Both then run darknet's host NMS (models/camera/decode.detections), as the JAX
predictor always does: the camera family has no compiled NMS to time.

Without shipped weights the output biases start at ultralytics' priors (models/camera/config.py
`prior_bias`), but the initial batch-norm statistics (mean 0, variance 1) let activations grow
through the deep stacks (Darknet53's boxes overflow to inf at 416); the 'random' variables
therefore carry batch statistics measured on a few street train images (as train/precise_bn.py
re-estimates them), a trained network's scale.
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from ...deploy.bench.model_setup import bench_variables
from ...deploy.bench.stages import cached_export, jax_throughput

STAGES = ("letterbox", "network_decode", "nms")
CALIBRATION_IMAGES = 32  # street train images, seed 0, as the RD bench's 32 samples


def camera_onnx_graph(det, variables, workdir: Path, int8: bool, input_hw) -> Path:
    """The export's directory (written once per worker), or its INT8 copy."""
    from ...data.camera.sources import load_camera_images
    from .export import export_camera
    from .quantize import quantize_camera

    return cached_export(workdir, f"{det.name}_camera",
                         lambda out: export_camera(det, variables, out, input_hw=tuple(input_hw), jax_export=False),
                         lambda fp32, out: quantize_camera(fp32, out, load_camera_images("street", "train",
                                                                                         CALIBRATION_IMAGES, seed=0)),
                         int8)


def camera_pipeline(det, variables, runtime: str, size: int, workdir: Path, threads: int, input_hw):
    """The CameraPipeline of one runtime: CameraPredictor (jax) or OrtCameraPredictor (onnx, onnx-int8)."""
    from .predict import CameraPredictor
    from .ort import OrtCameraPredictor

    if runtime == "jax":
        return CameraPredictor(det, variables, size=size)
    return OrtCameraPredictor(camera_onnx_graph(det, variables, workdir, runtime == "onnx-int8", input_hw),
                              threads=threads)


CAMERA_BN_IMAGES = 4  # street train images the stand-in variables' batch statistics are measured on


def measured_batch_stats(det, variables: dict, images: np.ndarray) -> dict:
    """`variables` with 'batch_stats' = the batch statistics of one train-mode forward on `images`
    (models/bn_statistics.py, train/precise_bn.py's estimate from one batch)."""
    from ...models.bn_statistics import batch_statistics

    return {"params": variables["params"], "batch_stats": batch_statistics(det)(variables, {"image": images})}


def camera_model_setup(name: str, size: int, overrides: dict | None = None):
    """A camera model: (detector, variables, weights label, one street test image). The classes are
    the shipped weights' run's, else the street benchmark's (what `dsfec train` gives a model trained
    on it); `overrides` (config fields) win."""
    from ... import zoo
    from ...data.camera.batches import eval_input
    from ...data.camera.letterbox import network_shape
    from ...data.camera.sources import load_camera_images, source_classes
    from ...models.camera.family import class_fields

    fields = {**class_fields(source_classes("street")),
              **zoo.trained_fields(zoo.shipped_weights(name), zoo.family_of(name).weight_fields), **(overrides or {})}
    det = zoo.create(name, **fields)
    variables, label = bench_variables(det, name)
    if label == "random":
        train = load_camera_images("street", "train", CAMERA_BN_IMAGES, seed=0)
        hw = network_shape(size, train[0].hw[0] / train[0].hw[1])
        variables = measured_batch_stats(det, variables, np.stack([eval_input(im, hw)[0] for im in train]))
    return det, variables, label, load_camera_images("street", "test", 1, seed=0)[0]


def camera_chain(image, pipeline) -> list:
    """[(stage, fn(previous output) -> output)] from a CameraImage to its Boxes2D in image pixels,
    through a modalities/image/predict.CameraPipeline (the JAX predictor or the ONNX Runtime one)."""
    from ...data.camera.letterbox import letterbox

    input_hw = pipeline.input_hw(image.hw)
    affine = letterbox(image.hw, input_hw)  # the map the letterbox stage applies (eval_input's)

    def nms(out):
        return pipeline.in_image(pipeline.postprocess(*out)[0], affine, image.hw)

    return [("letterbox", lambda _: pipeline.letterboxed([image], input_hw)[0]),
            ("network_decode", pipeline.decoded), ("nms", nms)]


CAMERA_SIZE = 416  # the long side camera images are letterboxed to (the paper's; street frames: 256 x 416)


def camera_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int,
                  size: int = CAMERA_SIZE, overrides: dict | None = None) -> dict:
    """runtime -> (chain of a camera model, record fields): one street test image letterboxed as
    CameraPredictor letterboxes it at `size`, into one fixed-size graph for ONNX Runtime.
    `overrides`: config fields (the tests' tiny networks)."""
    from .predict import decoding_network, letterbox_shape

    det, variables, label, image = camera_model_setup(name, size, overrides)
    input_hw = letterbox_shape(size, True, image.hw)  # CameraPredictor's rectangle: 256 x 416 at 416
    out = {}
    for rt in runtimes:
        pipeline = camera_pipeline(det, variables, rt, size, workdir, threads, input_hw)
        out[rt] = (camera_chain(image, pipeline), {"weights": label, "input_hw": list(input_hw)})
    if "jax" in out:
        network = decoding_network(det)
        out["jax"][1].update(jax_throughput(det, variables, jax.jit(lambda v, x: network(v, x["image"])),
                                            repeats, hw=input_hw))
    return out

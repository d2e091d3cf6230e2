"""The benchmark chains of a camera model (Shuffle-YOLOv3, Darknet53-YOLOv3; `dsfec bench`): each
runtime's chain IS its predictor's path, `CameraPipeline.stages` (modalities/image/predict.py,
STAGES): letterbox (host: the image scaled and centred into the network input), network_decode
(network and YOLOv3 decode), nms (darknet's host post-processing, models/camera/decode.detections),
to_image (the boxes mapped back to the image's pixels and renamed by the class map).

jax: CameraPredictor (the jitted network and YOLOv3 decode). onnx / onnx-int8: OrtCameraPredictor
over the export's graph (export_camera: network + decode; int8 quantizes the convolutions only,
calibrated on letterboxed street train images) with intra_op_num_threads = the worker's thread
count. The camera family has no compiled NMS: both run darknet's host NMS.

Without shipped weights the output biases start at ultralytics' priors (models/camera/config.py
`prior_bias`), but the initial batch-norm statistics (mean 0, variance 1) let activations grow
through the deep stacks (Darknet53's boxes overflow to inf at 416); the 'random' variables
therefore carry batch statistics measured on a few street train images (as train/precise_bn.py
re-estimates them), a trained network's scale.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...deploy.bench.model_setup import bench_variables
from ...deploy.bench.stages import cached_export, jax_throughput
from .predict import STAGES

__all__ = ["STAGES", "camera_chains", "measured_batch_stats"]

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
        return CameraPredictor(det, variables, size=size, constant_weights=True)
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


CAMERA_SIZE = 416  # the long side camera images are letterboxed to (the paper's; street frames: 256 x 416)


def camera_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int,
                  size: int = CAMERA_SIZE, overrides: dict | None = None) -> dict:
    """runtime -> (chain of a camera model, record fields): one street test image letterboxed as
    CameraPredictor letterboxes it at `size`, into one fixed-size graph for ONNX Runtime.
    `overrides`: config fields (the tests' tiny networks)."""
    from .predict import letterbox_shape

    det, variables, label, image = camera_model_setup(name, size, overrides)
    input_hw = letterbox_shape(size, True, image.hw)  # CameraPredictor's rectangle: 256 x 416 at 416
    out, pipelines = {}, {}
    for rt in runtimes:
        pipelines[rt] = camera_pipeline(det, variables, rt, size, workdir, threads, input_hw)
        out[rt] = (pipelines[rt].stages([image], pipelines[rt].input_hw(image.hw)),
                   {"weights": label, "input_hw": list(input_hw)})
    if "jax" in out:  # the predictor's own jitted network and decode at batch 1 .. 8
        jax_pipeline = pipelines["jax"]
        out["jax"][1].update(jax_throughput(det, jax_pipeline.variables, lambda v, x: jax_pipeline.network(v, x["image"]),
                                            repeats, hw=input_hw))
    return out

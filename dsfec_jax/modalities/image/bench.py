"""The network + decode stage of each runtime for a camera model (Shuffle-YOLOv3, Darknet53-YOLOv3),
as the pipelines that also letterbox and post-process (predict_camera.CameraPipeline), so every
runtime's chain shares the host stages and differs by the network alone.

jax: CameraPredictor (the jitted network and YOLOv3 decode). onnx / onnx-int8: the export's graph
(export_camera: network + decode; int8 quantizes the convolutions only, calibrated on letterboxed
street train images) in ONNX Runtime with intra_op_num_threads = the worker's thread count, through
OrtCameraPredictor. Both then run darknet's host NMS (models/camera/decode.detections), as the JAX
predictor always does: the camera family has no compiled NMS to time.
"""

from __future__ import annotations

from pathlib import Path

from ...deploy.bench.stages import cached_export

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

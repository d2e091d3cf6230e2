"""Run a camera export (export_camera) with ONNX Runtime, from images to boxes in image pixels, with
the interface of the JAX `CameraPredictor` (modalities/image/predict.CameraPipeline: the same letterbox on the
host, the same darknet post-processing and the same mapping back to the image; only the network and
decode run in ONNX Runtime).

The graph takes one letterboxed size (deploy.json's input_hw and letterbox rule): images are fed as
CameraPredictor would feed them at that size, and an image whose own rectangle is another size is
refused by name (a square export takes every image).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from ...models.camera.config import INPUT
from ...models.camera.decode import EVAL_SCORE, MAX_DETECTIONS, NMS_IOU
from .predict import CameraPipeline, letterbox_shape
from .export import OUTPUTS
from ...deploy.ort import ort_session, read_manifest, run_fixed_batch


def graph_input_hw(manifest: dict, image_hw, where) -> tuple[int, int]:
    """The input an image of `image_hw` is letterboxed into under the export's rule; a ValueError
    naming `where` when that is not the graph's size."""
    rule, want = manifest["letterbox"], tuple(manifest["input_hw"])
    hw = letterbox_shape(int(rule["size"]), bool(rule["rect"]), image_hw)
    if hw != want:
        raise ValueError(f"{where}: an image of {image_hw[0]} x {image_hw[1]} letterboxes into {hw} at size "
                         f"{rule['size']}, the graph takes {want}; export with `--input-hw {hw[0]},{hw[1]}`, or a "
                         "square --input-hw S,S (every image letterboxed into the square)")
    return hw


class OrtCameraPredictor(CameraPipeline):
    """`OrtCameraPredictor(DIR)(image) -> Boxes2D` (image pixels) with onnxruntime on the CPU;
    thresholds default to darknet's evaluation settings (score 0.005, NMS IoU 0.45, 300 boxes);
    `class_map` as CameraPredictor's; `threads`: ONNX Runtime's intra-op pool (None: its default)."""

    def __init__(self, export_dir: str | Path, score_threshold: float = EVAL_SCORE, nms_iou: float = NMS_IOU,
                 max_detections: int = MAX_DETECTIONS, class_map: Mapping[str, str] | None = None,
                 threads: int | None = None):
        self.model_path, self.manifest = read_manifest(export_dir, "image")
        rule = self.manifest["letterbox"]
        self._setup(self.manifest["model"], self.manifest["classes"], rule["size"], rule["rect"], score_threshold,
                    nms_iou, max_detections, class_map)
        self.batch_size = int(self.manifest["batch_size"])
        self.session = ort_session(self.model_path, threads)

    def input_hw(self, image_hw) -> tuple[int, int]:
        return graph_input_hw(self.manifest, image_hw, self.model_path)

    def decoded(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        feeds = {INPUT: np.asarray(images, np.float32)}
        return run_fixed_batch(lambda f: self.session.run(list(OUTPUTS), f), feeds, self.batch_size, self.model_path)

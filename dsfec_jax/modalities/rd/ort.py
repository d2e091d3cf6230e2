"""Run an RD export (export_rd) with ONNX Runtime, from RD samples to boxes in map pixels, with the
interface of the JAX `RDPredictor` (modalities/rd/predict.RDPipeline: the same representations on the host and
the same conversion back to map pixels).

The graph gives each anchor's decoded box and class scores; the pipeline's `postprocess`
(models/yolo_rd/decode_host.host_detections), the JAX predictor's own, then runs on the host:
class-aware greedy NMS over the multi-label (anchor, class)
candidates (boxes/nms2d.detect_host, which keeps what the compiled nms2d.detect_jax keeps), or, for
YOLOv10, the NMS-free top-k of models/yolo_rd/decode_v10.top_detections. Outputs are padded to
max_detections as the compiled ones are.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...models.yolo_rd.decode import EVAL_CONF, EVAL_IOU, EVAL_MAX_DET
from .predict import RDPipeline
from .export import OUTPUTS, representation_of
from ...deploy.ort import ort_session, read_manifest, run_fixed_batch


class OrtRDPredictor(RDPipeline):
    """`OrtRDPredictor(DIR)(sample) -> Boxes2D` (map pixels) with onnxruntime on the CPU; thresholds
    default to the paper's evaluation settings (conf 0.001, NMS IoU 0.1, at most 300 boxes)."""

    def __init__(self, export_dir: str | Path, score_threshold: float = EVAL_CONF, nms_iou: float = EVAL_IOU,
                 max_detections: int = EVAL_MAX_DET, threads: int | None = None):
        self.model_path, self.manifest = read_manifest(export_dir, "rd")
        self.classes = tuple(self.manifest["classes"])
        self.representation = representation_of(self.manifest)
        self.input_names = tuple(self.manifest["inputs"])
        self.kind = self.manifest["postprocess"]["kind"]
        self.score_threshold, self.nms_iou, self.max_detections = score_threshold, nms_iou, max_detections
        self.batch_size = int(self.manifest["batch_size"])
        self.session = ort_session(self.model_path, threads)

    def decoded(self, inputs: dict) -> tuple[np.ndarray, np.ndarray]:
        """The graph's outputs: boxes (B, A, 4) xyxy input pixels and class scores (B, A, nc)."""
        feeds = {k: np.asarray(inputs[k], np.float32) for k in self.input_names}
        check_input_size(self.manifest, feeds, self.model_path)
        return run_fixed_batch(lambda f: self.session.run(list(OUTPUTS), f), feeds, self.batch_size, self.model_path)


def check_input_size(manifest: dict, feeds: dict, where) -> None:
    """A clear error when maps were fitted to another size than the graph's."""
    want = tuple(manifest["input_hw"])
    for name, array in feeds.items():
        if tuple(array.shape[1:3]) != want:
            raise ValueError(f"{where}: input {name!r} is {tuple(array.shape[1:3])}, the graph takes {want}; "
                             f"export with input_hw covering the maps (`dsfec export --input-hw`) or fit='resize'")

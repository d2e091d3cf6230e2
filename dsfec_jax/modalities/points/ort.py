"""Run a point-cloud export (modalities/points/export.py) with ONNX Runtime, from raw points to
boxes, with the same interface as the JAX `Predictor` (pillarize and NMS on the host are the same
code)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.grid import Grid
from ...data.points.pillarize import PillarSpec
from ...deploy.ort import ort_session, read_manifest, run_fixed_batch
from .predict import HostPipeline


def pillar_spec(manifest: dict) -> PillarSpec:
    p = manifest["pillars"]
    grid = Grid(**{k: tuple(v) if isinstance(v, list) else v for k, v in p["grid"].items()})
    return PillarSpec(grid, tuple(p["features"]), int(p["max_pillars"]), int(p["max_points"]))


class OrtPredictor(HostPipeline):
    """`OrtPredictor(DIR)(points_NxF | Frame) -> Detections` with onnxruntime on the CPU."""

    def __init__(self, path: str | Path, score_threshold: float = 0.1, nms_iou: float = 0.2, max_boxes: int = 500,
                 threads: int | None = None):
        self.model_path, self.manifest = read_manifest(path, "points")
        heads = {h: tuple(c) for h, c in self.manifest["head_classes"].items()}
        self._setup(pillar_spec(self.manifest), heads, score_threshold, nms_iou, max_boxes)
        self.session = ort_session(self.model_path, threads)
        self.batch_size = int(self.manifest["batch_size"])

    def run(self, batch: dict):
        feeds = {k: np.asarray(batch[k]) for k in self.manifest["inputs"]}
        return run_fixed_batch(lambda f: self.session.run(["boxes", "scores", "labels"], f), feeds, self.batch_size,
                               self.model_path)

"""Run an exported detector with ONNX Runtime, from raw points to boxes, with the same
interface as the JAX `Predictor` (pillarize and NMS on the host are the same code)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..data.points.pillarize import PillarSpec
from ..core.grid import Grid
from ..predict import HostPipeline


def read_manifest(path: str | Path) -> tuple[Path, dict]:
    """DIR or DIR/model.onnx -> (model path, deploy.json contents)."""
    path = Path(path)
    model = path / "model.onnx" if path.is_dir() else path
    manifest = model.parent / "deploy.json"
    for p in (model, manifest):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: missing; export with `dsfec export --model NAME --out DIR`")
    return model, json.loads(manifest.read_text())


def pillar_spec(manifest: dict) -> PillarSpec:
    p = manifest["pillars"]
    grid = Grid(**{k: tuple(v) if isinstance(v, list) else v for k, v in p["grid"].items()})
    return PillarSpec(grid, tuple(p["features"]), int(p["max_pillars"]), int(p["max_points"]))


class OrtPredictor(HostPipeline):
    """`OrtPredictor(DIR)(points_NxF | Frame) -> Detections` with onnxruntime on the CPU."""

    def __init__(self, path: str | Path, score_threshold: float = 0.1, nms_iou: float = 0.2, max_boxes: int = 500,
                 threads: int | None = None):
        import onnxruntime as ort

        self.model_path, self.manifest = read_manifest(path)
        heads = {h: tuple(c) for h, c in self.manifest["head_classes"].items()}
        self._setup(pillar_spec(self.manifest), heads, score_threshold, nms_iou, max_boxes)
        options = ort.SessionOptions()
        if threads:
            options.intra_op_num_threads = threads
            options.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(self.model_path), options, providers=["CPUExecutionProvider"])
        self.batch_size = int(self.manifest["batch_size"])

    def run(self, batch: dict):
        n = len(batch["points"])
        if n != self.batch_size:  # the graph has a fixed batch: run frame by frame (batch 1) or refuse
            if self.batch_size != 1:
                raise ValueError(f"{self.model_path}: exported for batch {self.batch_size}, got {n} frames")
            parts = [self.run({k: v[i:i + 1] for k, v in batch.items()}) for i in range(n)]
            return tuple(np.concatenate([p[j] for p in parts]) for j in range(3))
        feeds = {k: np.asarray(batch[k]) for k in self.manifest["inputs"]}
        return tuple(self.session.run(["boxes", "scores", "labels"], feeds))

"""The benchmark chains of a point model (`dsfec bench`; deploy/bench times them), raw points to
boxes: each runtime's chain IS its predictor's path, `HostPipeline.stages` (modalities/points/
predict.py, STAGES): pillarize (host numpy), network_decode (pillar net .. heads, then the family's
decode: sigmoid, PIXOR decode, top-k per head), nms (host, rotated, per class).

jax: the JAX Predictor (one jit of network + decode, on the fewest pillar slots that hold the
frame). onnx / onnx-int8: OrtPredictor over the export (modalities/points/export.py: network + decode
in one graph at the model's pillar slots; int8 quantizes the network only, calibrated on synthetic
train frames) with intra_op_num_threads = the worker's thread count and the JAX predictor's NMS
settings. Also JAX's throughput of network + decode at batch sizes above 1, which the batch-1
chains do not show.
"""

from __future__ import annotations

from pathlib import Path

from ...deploy.bench.model_setup import bench_variables
from ...deploy.bench.stages import cached_export, jax_throughput
from .predict import STAGES

__all__ = ["STAGES", "point_chains"]

CALIBRATION_FRAMES = 32  # synthetic train frames, seed 0


def model_setup(name: str):
    """A point model: (detector, variables, weights label, frame points)."""
    from ... import zoo
    from ...core.defaults import RUN_PILLARS
    from ...data.points.pillarize import select_columns
    from ...data.points.sources import load_frames

    det = zoo.create(name, max_pillars=RUN_PILLARS)
    variables, label = bench_variables(det, name)
    frame = load_frames("synthetic", "test", 1, seed=0)[0]
    return det, variables, label, select_columns(frame, det.config.point_features)


def point_export(det, variables, workdir: Path, int8: bool) -> Path:
    """The export's directory at the JAX predictor's top-k (written once per worker), or its INT8 copy."""
    from ... import zoo
    from ...data.points.sources import load_frames
    from .export import export
    from .quantize import quantize

    top_k = zoo.family_of(det.config).points.predictor["top_k"]
    return cached_export(workdir, f"{det.name}_points", lambda out: export(det, variables, out, top_k=top_k),
                         lambda fp32, out: quantize(fp32, out, load_frames("synthetic", "train", CALIBRATION_FRAMES,
                                                                           seed=0)),
                         int8)


def point_predictor(det, variables, runtime: str, workdir: Path, threads: int, jax_predictor):
    """The HostPipeline of one runtime: the JAX Predictor, or OrtPredictor with its NMS settings."""
    from .ort import OrtPredictor

    if runtime == "jax":
        return jax_predictor
    return OrtPredictor(point_export(det, variables, workdir, runtime == "onnx-int8"),
                        score_threshold=jax_predictor.score_threshold, nms_iou=jax_predictor.nms_iou,
                        max_boxes=jax_predictor.max_boxes, threads=threads)


def point_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int) -> dict:
    """runtime -> (chain of a point model: its predictor's stages on one frame, record fields)."""
    from .predict import Predictor

    det, variables, label, points = model_setup(name)
    jax_predictor = Predictor(det, variables, score_threshold=0.1, constant_weights=True)
    out = {}
    for rt in runtimes:
        predictor = point_predictor(det, variables, rt, workdir, threads, jax_predictor)
        out[rt] = (predictor.stages([points]), {"weights": label, "points": int(len(points))})
    if "jax" in out:  # the predictor's own jitted network and decode at batch 1 .. 8
        out["jax"][1].update(jax_throughput(det, jax_predictor.variables, jax_predictor.network, repeats))
    return out

"""From raw radar points to scored oriented boxes: pillarize (host, numpy) -> jitted network and
decode -> rotated NMS per class (host)."""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import numpy as np

from ... import zoo
from ...boxes import priors
from ...boxes.nms import batched_rotated_nms
from ...boxes.structures import Boxes
from ...data.points.frame import Frame
from ...core.progress import FIRST_BATCH, bar
from ...data.points.pillarize import PillarSpec, pillarize, select_columns
from ..inference import InferenceVariables
from ..stages import Stages, carrying, run as run_stages


def head_classes(cfg) -> dict:
    """Head name -> its classes (DSFEC's Car/Truck/VRU heads, a CenterHead's single one, ...)."""
    return zoo.family_of(cfg).head_classes(cfg)


def decoder(cfg, top_k: int):
    """fn(head outputs) -> (boxes, scores, labels): the top-k decoded candidates before NMS
    (what the jitted predictors run after the network, and what `deploy.export` writes to ONNX)."""
    return zoo.family_of(cfg).points.decoder(cfg, top_k)


def decoded_network(detector, top_k: int):
    """fn(variables, inputs) -> (boxes, scores, labels): network then `decoder`."""
    decode = decoder(detector.config, top_k)
    return lambda v, x: decode(detector.apply(v, x))


class Detections(NamedTuple):
    boxes: Boxes
    scores: np.ndarray


STAGES = ("pillarize", "network_decode", "nms")  # the predictor's path (`HostPipeline.stages`)


class HostPipeline:
    """What every runtime shares: pillarize on the host, run the network + decode (the runtime's
    `run`), rotated NMS per class on the host. A subclass sets the fields and `run(batch)`."""

    def _setup(self, spec: PillarSpec, head_classes: dict, score_threshold: float, nms_iou: float,
               max_boxes: int) -> None:
        self.spec, self.head_classes = spec, head_classes
        self.class_names = [c for classes in head_classes.values() for c in classes]
        self.score_threshold, self.nms_iou, self.max_boxes = score_threshold, nms_iou, max_boxes

    def run(self, batch: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def __call__(self, points) -> Detections:
        return self._detect([points])[0]

    def predict_samples(self, frames: Sequence[Frame], batch_size: int = 8,
                        progress: bool = False) -> dict[str, Detections]:
        """frame id -> detections, `batch_size` frames a network call (every modality's predictor
        has this verb: modalities/base.py); `progress`: a bar over the batches on stderr."""
        out = {}
        for start in bar(range(0, len(frames), batch_size), f"detecting in {len(frames)} frames", first=FIRST_BATCH,
                         enabled=progress, unit="batch"):
            chunk = [frames[i] for i in range(start, min(start + batch_size, len(frames)))]
            for frame, found in zip(chunk, self._detect(chunk)):
                out[frame.frame_id] = found
        return out

    def _detect(self, items: list) -> list[Detections]:
        """Detections of one batch of point arrays or Frames, in order."""
        return run_stages(self.stages(items))

    def stages(self, items: Sequence) -> Stages:
        """Point arrays or Frames -> their Detections, stage by stage (STAGES): what the predictor
        runs and `dsfec bench` times."""
        def pillarized(_):
            arrays = [select_columns(p, self.spec.features) if isinstance(p, Frame) else np.asarray(p, np.float32)
                      for p in items]
            tensors = [pillarize(a, self.spec)[0] for a in arrays]
            return {k: np.stack([t[k] for t in tensors]) for k in tensors[0]}, [bool(t["mask"].any()) for t in tensors]

        def nms(pair):
            (boxes, scores, labels), sensed = pair
            # A frame with no point on the grid sensed nothing, so it reports nothing: the network
            # would still answer from its biases and from the zero padding at the grid's edge
            # (shipped DSFEC-S: 59 low-score edge "cars" on an empty cloud).
            return [self._postprocess(*(out if any_point else self._nothing()))
                    for any_point, out in zip(sensed, zip(boxes, scores, labels))]

        return [("pillarize", pillarized), ("network_decode", carrying(self.run)), ("nms", nms)]

    def predict_tensors(self, batch: dict) -> list[Detections]:
        """Detections of a batch of pillar tensors, exactly as the network and NMS give them."""
        boxes, scores, labels = self.run(batch)
        return [self._postprocess(b, s, l) for b, s, l in zip(boxes, scores, labels)]

    def _nothing(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # no box: BEV (5 columns) and 3D (7) decodes give the same empty Boxes
        return np.zeros((0, 5), np.float32), np.zeros(0, np.float32), np.zeros(0, np.int32)

    def _postprocess(self, boxes, scores, labels) -> Detections:
        """Rotated NMS per class, then Boxes. The decoded width says what the network predicts:
        5 columns (x, y, w, l, yaw: DSFEC's BEV heads; z and height from the class priors) or
        7 (x, y, z, w, l, h, yaw: a CenterHead's 3D boxes, NMS on their BEV footprints)."""
        full3d = boxes.shape[-1] == 7
        bev = boxes[:, [0, 1, 3, 4, 6]] if full3d else boxes
        keep = batched_rotated_nms(bev.astype(np.float64), scores, labels, self.nms_iou,
                                   max_output=self.max_boxes, score_threshold=self.score_threshold)
        boxes, scores, labels = boxes[keep].astype(np.float32), scores[keep], labels[keep]
        names = np.array([self.class_names[i] for i in labels], dtype="<U16")
        if full3d:
            out = Boxes(boxes[:, :3], boxes[:, 3:6], boxes[:, 6], np.zeros((len(keep), 2), np.float32), names)
            return Detections(out, scores.astype(np.float32))
        h = np.array([priors.height(n) for n in names], np.float32)
        z = np.array([priors.centre_z(n) for n in names], np.float32)
        out = Boxes(np.column_stack([boxes[:, :2], z]).astype(np.float32),
                    np.column_stack([boxes[:, 2:4], h]).astype(np.float32),
                    boxes[:, 4].astype(np.float32), np.zeros((len(keep), 2), np.float32), names)
        return Detections(out, scores.astype(np.float32))


class Predictor(InferenceVariables, HostPipeline):
    """`predictor(points_NxF | Frame) -> Detections` with the jitted JAX network and decode.
    Points' columns follow the model's `point_features` unless a Frame (named columns) is given.
    `top_k`, `nms_iou` and `max_boxes` default to the family's (Family.predictor): DSFEC 100 /
    0.2 / 500; RadarNeXt the public config's 500 decoded candidates, IoU 0.2 on the BEV
    footprints of its 3D boxes, at most 83 boxes a frame."""

    def __init__(self, detector, variables, score_threshold: float = 0.1, top_k: int | None = None,
                 nms_iou: float | None = None, max_boxes: int | None = None, constant_weights: bool = False):
        cfg = detector.config
        given = {"top_k": top_k, "nms_iou": nms_iou, "max_boxes": max_boxes}
        options = {**zoo.family_of(cfg).points.predictor, **{k: v for k, v in given.items() if v is not None}}
        self.detector = self._inference_detector(detector)  # its inference form (modalities/inference.py)
        self.variables, self.constant_weights = variables, constant_weights
        self._setup(PillarSpec.of(cfg), head_classes(cfg), score_threshold, options["nms_iou"], options["max_boxes"])
        self.network = jax.jit(decoded_network(self.detector, options["top_k"]))

    def run(self, batch: dict):
        return jax.device_get(self.call_network(fewest_slots(batch)))


SLOT_BUCKET = 256  # the JAX predictor's pillar-slot sizes: 256, 512, 1024, ... up to max_pillars


def fewest_slots(batch: dict) -> dict:
    """The pillar tensors cut to the smallest bucket (SLOT_BUCKET * 2^k, or all slots) that holds
    every frame's last occupied slot (`pillarize` packs occupied pillars first). The network masks
    the padding, so the outputs are the same; a sparse radar frame then skips most of the slots'
    pillar-net work (the gain: docs/points-deploy.md; `dsfec bench --models dsfec_s --runtimes jax
    --threads 1` re-measures).
    jax.jit compiles once per bucket; an exported ONNX graph keeps its fixed slot count."""
    slots = batch["mask"].shape[1]
    occupied = np.flatnonzero(np.asarray(batch["mask"]).any(axis=(0, 2)))
    used = int(occupied[-1]) + 1 if occupied.size else 0
    bucket = SLOT_BUCKET
    while bucket < used:
        bucket *= 2
    if bucket >= slots:
        return batch
    return {k: (v[:, :bucket] if k in ("points", "mask", "coords") else v) for k, v in batch.items()}


def predictor_for(detector, variables, **options) -> HostPipeline:
    """The JAX predictor of a detector, with its family's defaults (kept for callers of the old API)."""
    return Predictor(detector, variables, **options)

"""From raw radar points to scored oriented boxes: pillarize (host, numpy) -> jitted network and
decode -> rotated NMS per class (host)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from .boxes import priors
from .boxes.center_decode import decode_center_head
from .boxes.decode import decode_heads
from .boxes.nms import batched_rotated_nms
from .boxes.pixor import cell_centres
from .boxes.structures import Boxes
from .data.frame import Frame
from .data.pillarize import PillarSpec, pillarize, select_columns
from .models.dsfec import HEAD_NAMES


def head_classes(cfg) -> dict:
    """Head name -> its classes: DSFEC's Car/Truck/VRU heads, or a CenterHead's single one."""
    return {"center": tuple(cfg.classes)} if cfg.family == "radarnext" else dict(zip(HEAD_NAMES, cfg.head_classes))


def decoder(cfg, top_k: int):
    """fn(head outputs) -> (boxes, scores, labels): the top-k decoded candidates before NMS
    (what the jitted predictors run after the network, and what `deploy.export` writes to ONNX)."""
    if cfg.family == "radarnext":
        return lambda maps: decode_center_head(maps, cfg.grid, cfg.output_stride, top_k)
    cells, heads = cell_centres(cfg.grid, cfg.output_stride), head_classes(cfg)
    return lambda maps: decode_heads(maps, heads, cells, top_k)


def decoded_network(detector, top_k: int):
    """fn(variables, inputs) -> (boxes, scores, labels): network then `decoder`."""
    decode = decoder(detector.config, top_k)
    return lambda v, x: decode(detector.apply(v, x))


class Detections(NamedTuple):
    boxes: Boxes
    scores: np.ndarray


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
        return self.predict_batch([points])[0]

    def predict_batch(self, items: list) -> list[Detections]:
        arrays = [select_columns(p, self.spec.features) if isinstance(p, Frame) else np.asarray(p, np.float32)
                  for p in items]
        tensors = [pillarize(a, self.spec)[0] for a in arrays]
        batch = {k: np.stack([t[k] for t in tensors]) for k in tensors[0]}
        # A frame with no point on the grid sensed nothing, so it reports nothing: the network
        # would still answer from its biases and from the zero padding at the grid's edge
        # (shipped DSFEC-S: 59 low-score edge "cars" on an empty cloud).
        return [det if t["mask"].any() else self._postprocess(*self._nothing())
                for det, t in zip(self.predict_tensors(batch), tensors)]

    def predict_tensors(self, batch: dict) -> list[Detections]:
        """Detections of a batch of pillar tensors, exactly as the network and NMS give them."""
        boxes, scores, labels = self.run(batch)
        return [self._postprocess(b, s, l) for b, s, l in zip(boxes, scores, labels)]

    def _nothing(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        width = 7 if "center" in self.head_classes else 5  # a CenterHead decodes 3D boxes
        return np.zeros((0, width), np.float32), np.zeros(0, np.float32), np.zeros(0, np.int32)

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


class Predictor(HostPipeline):
    """`predictor(points_NxF | Frame) -> Detections` with the jitted JAX network and decode.
    Points' columns follow the model's `point_features` unless a Frame (named columns) is given."""

    def __init__(self, detector, variables, score_threshold: float = 0.1, top_k: int = 100,
                 nms_iou: float = 0.2, max_boxes: int = 500):
        cfg = detector.config
        self.detector, self.variables = detector, variables
        self._setup(PillarSpec.of(cfg), head_classes(cfg), score_threshold, nms_iou, max_boxes)
        self.network = jax.jit(decoded_network(detector, top_k))

    def run(self, batch: dict):
        return jax.device_get(self.network(self.variables, batch))


class CenterPredictor(Predictor):
    """The same pipeline for CenterHead detectors (RadarNeXt), with the public config's defaults:
    3D boxes come out of the network (centre z and height included); rotated NMS per class on
    their BEV footprints (IoU 0.2), 500 decoded candidates, at most 83 boxes per frame after NMS."""

    def __init__(self, detector, variables, score_threshold: float = 0.1, top_k: int = 500,
                 nms_iou: float = 0.2, max_boxes: int = 83):
        super().__init__(detector, variables, score_threshold, top_k, nms_iou, max_boxes)


def predictor_for(detector, variables, **options) -> HostPipeline:
    """The JAX predictor matching the detector's head (dense PIXOR heads or a CenterHead)."""
    cls = CenterPredictor if detector.config.family == "radarnext" else Predictor
    return cls(detector, variables, **options)

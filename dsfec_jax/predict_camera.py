"""From camera images to scored 2D boxes: letterbox (host) -> jitted network and YOLOv3 decode ->
darknet's host post-processing (score > 0.005, per-class NMS at IoU 0.45, the 300 best;
models/camera/decode.py) -> boxes back in the original image's pixels, with class names.

Each image is letterboxed into its own rectangle (data/camera/letterbox.py: long side `size`,
short side rounded up to 32; `rect=False`: size x size squares), images of one input shape run as
one batch, and the jitted network compiles once per input shape. `class_map` (model class -> name
to report, data/camera/sources.class_map) renames the detections into a data source's vocabulary
and drops classes it does not have; the predictor's `classes` are then the reported names.
"""

from __future__ import annotations

import dataclasses
from typing import Mapping, Sequence

import jax
import numpy as np

from . import zoo
from .boxes.boxes2d import Boxes2D
from .data.camera.batches import eval_input
from .data.camera.images import CameraImage
from .data.camera.letterbox import network_shape
from .models.camera.decode import EVAL_SCORE, MAX_DETECTIONS, NMS_IOU, decode, detections, rescale


def decoding_network(detector):
    """fn(variables, image (B, H, W, 3)) -> (boxes (B, N, 4) xyxy input pixels, scores (B, N, C))."""
    return lambda variables, image: decode(detector.apply(variables, {"image": image}))


class CameraPredictor:
    """`predictor(image) -> Boxes2D` (original image pixels, scores) with the jitted JAX network."""

    def __init__(self, detector, variables, size: int = 416, rect: bool = True,
                 score_threshold: float = EVAL_SCORE, nms_iou: float = NMS_IOU,
                 max_detections: int = MAX_DETECTIONS, class_map: Mapping[str, str] | None = None):
        zoo.require_modality(detector.config, "image", "CameraPredictor")
        self.detector, self.variables, self.size, self.rect = detector, variables, int(size), rect
        self.score_threshold, self.nms_iou, self.max_detections = score_threshold, nms_iou, max_detections
        self.model_classes = tuple(detector.config.classes)
        self.class_map = dict(class_map) if class_map is not None else {c: c for c in self.model_classes}
        unknown = sorted(set(self.class_map) - set(self.model_classes))
        if unknown:
            raise ValueError(f"class_map names {unknown}, not classes of {detector.name} {self.model_classes}")
        self.classes = tuple(dict.fromkeys(self.class_map.values()))
        self.network = jax.jit(decoding_network(detector))

    def input_hw(self, image_hw) -> tuple[int, int]:
        """The network input an image of `image_hw` is letterboxed into."""
        return network_shape(self.size, image_hw[0] / image_hw[1]) if self.rect else (self.size, self.size)

    def __call__(self, image) -> Boxes2D:
        """One image: a CameraImage, or (H, W, 3) uint8 RGB."""
        if not isinstance(image, CameraImage):
            image = CameraImage("image", np.asarray(image), Boxes2D.empty())
        return self.predict_images([image])[image.image_id]

    def predict_images(self, images: Sequence[CameraImage], batch_size: int = 8) -> dict[str, Boxes2D]:
        """image id -> detections in that image's pixels, batches of one input shape at a time."""
        out = {}
        for start in range(0, len(images), batch_size):
            chunk = [images[i] for i in range(start, min(start + batch_size, len(images)))]
            groups: dict[tuple[int, int], list[int]] = {}
            for k, item in enumerate(chunk):
                groups.setdefault(self.input_hw(item.hw), []).append(k)
            for hw, members in groups.items():
                prepared = [eval_input(chunk[k], hw) for k in members]
                boxes, scores = jax.device_get(self.network(self.variables, np.stack([p[0] for p in prepared])))
                found = detections(boxes, scores, self.model_classes, score_threshold=self.score_threshold,
                                   iou_threshold=self.nms_iou, max_detections=self.max_detections)
                for k, (_, affine), dets in zip(members, prepared, found):
                    out[chunk[k].image_id] = self._in_image(dets, affine, chunk[k].hw)
        return out

    def _in_image(self, dets: Boxes2D, affine, image_hw) -> Boxes2D:
        """Input-pixel detections -> the image's pixels (clipped), renamed by the class map."""
        xyxy = rescale(dets.xyxy, np.array([affine.sx, affine.sy]), np.array([affine.ox, affine.oy]), image_hw)
        keep = np.array([str(n) in self.class_map for n in dets.names], bool)
        names = np.array([self.class_map[str(n)] for n in dets.names[keep]], dtype="<U32")
        return dataclasses.replace(dets.select(keep), xyxy=xyxy[keep], names=names)

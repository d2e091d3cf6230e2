"""From camera images to scored 2D boxes: letterbox (host) -> jitted network and YOLOv3 decode ->
darknet's host post-processing (score > 0.005, per-class NMS at IoU 0.45, the 300 best;
models/camera/decode.py) -> boxes back in the original image's pixels, with class names.

Each image is letterboxed into its own rectangle (data/camera/letterbox.py: long side `size`,
short side rounded up to 32; `rect=False`: size x size squares), images of one input shape run as
one batch, and the jitted network compiles once per input shape. `class_map` (model class -> name
to report, data/camera/sources.class_map) renames the detections into a data source's vocabulary
and drops classes it does not have; the predictor's `classes` are then the reported names.

`CameraPipeline` is everything but the network: the ONNX Runtime predictor (modalities/image/ort.py)
and the bench's chains (modalities/image/bench.py) run the same letterbox and host
post-processing around their own network, so every runtime's detections differ by the network alone.
"""

from __future__ import annotations

import dataclasses
from typing import Mapping, Sequence

import jax
import numpy as np

from ..checks import require_modality
from ..inference import InferenceVariables
from ..stages import Stages, carrying, run as run_stages
from ...core.progress import FIRST_BATCH, bar, stage
from ...boxes.boxes2d import Boxes2D
from ...data.camera.batches import eval_input
from ...data.camera.images import CameraImage
from ...data.camera.letterbox import Affine, network_shape
from ...models.camera.decode import EVAL_SCORE, MAX_DETECTIONS, NMS_IOU, decode, detections, rescale


def decoding_network(detector):
    """fn(variables, image (B, H, W, 3)) -> (boxes (B, N, 4) xyxy input pixels, scores (B, N, C))."""
    return lambda variables, image: decode(detector.apply(variables, {"image": image}))


def letterbox_shape(size: int, rect: bool, image_hw) -> tuple[int, int]:
    """The network input an image of `image_hw` is letterboxed into: its own rectangle with long side
    `size` (`rect`), or the size x size square."""
    return network_shape(size, image_hw[0] / image_hw[1]) if rect else (size, size)


def as_camera_image(image) -> CameraImage:
    """A CameraImage as it is, or (H, W, 3) uint8 RGB wrapped as one (id 'image', no boxes)."""
    return image if isinstance(image, CameraImage) else CameraImage("image", np.asarray(image), Boxes2D.empty())


STAGES = ("letterbox", "network_decode", "nms", "to_image")  # the predictor's path (`CameraPipeline.stages`)


class CameraPipeline:
    """What every runtime shares: the letterbox (host), the runtime's `decoded(images)` (network and
    YOLOv3 decode), darknet's host post-processing, boxes back in image pixels renamed by the class
    map. A subclass calls `_setup` and defines `decoded`."""

    def _setup(self, model: str, model_classes, size: int, rect: bool, score_threshold: float, nms_iou: float,
               max_detections: int, class_map: Mapping[str, str] | None) -> None:
        self.size, self.rect = int(size), rect
        self.score_threshold, self.nms_iou, self.max_detections = score_threshold, nms_iou, max_detections
        self.model_classes = tuple(model_classes)
        self.class_map = dict(class_map) if class_map is not None else {c: c for c in self.model_classes}
        unknown = sorted(set(self.class_map) - set(self.model_classes))
        if unknown:
            raise ValueError(f"class_map names {unknown}, not classes of {model} {self.model_classes}")
        self.classes = tuple(dict.fromkeys(self.class_map.values()))

    def decoded(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Letterboxed images (B, H, W, 3) float32 in [0, 1] -> (boxes (B, N, 4) xyxy input pixels,
        scores (B, N, C)) as numpy."""
        raise NotImplementedError

    def input_hw(self, image_hw) -> tuple[int, int]:
        """The network input an image of `image_hw` is letterboxed into."""
        return letterbox_shape(self.size, self.rect, image_hw)

    def __call__(self, image) -> Boxes2D:
        """One image: a CameraImage, or (H, W, 3) uint8 RGB."""
        image = as_camera_image(image)
        return self.predict_samples([image])[image.image_id]

    def letterboxed(self, items: Sequence[CameraImage], input_hw) -> tuple[np.ndarray, list[Affine]]:
        """Images of one input shape -> (the batch (B, H, W, 3) float32, each image -> input map)."""
        prepared = [eval_input(item, input_hw) for item in items]
        return np.stack([p[0] for p in prepared]), [p[1] for p in prepared]

    def postprocess(self, boxes, scores) -> list[Boxes2D]:
        """Decoded candidates -> per image the kept detections in input pixels, model class names."""
        return detections(boxes, scores, self.model_classes, score_threshold=self.score_threshold,
                          iou_threshold=self.nms_iou, max_detections=self.max_detections)

    def predict_samples(self, images: Sequence[CameraImage], batch_size: int = 8,
                        progress: bool = False) -> dict[str, Boxes2D]:
        """image id -> detections in that image's pixels, batches of one input shape at a time;
        `progress`: a bar over the batches on stderr (the commands' eval and predict)."""
        out, shapes = {}, set()
        for start in bar(range(0, len(images), batch_size), f"detecting in {len(images)} images", first=FIRST_BATCH,
                         enabled=progress, unit="batch"):
            chunk = [images[i] for i in range(start, min(start + batch_size, len(images)))]
            groups: dict[tuple[int, int], list[CameraImage]] = {}
            for item in chunk:
                groups.setdefault(self.input_hw(item.hw), []).append(item)
            for hw, members in groups.items():
                # photos of other aspect ratios letterbox to other shapes: each new one compiles again,
                # for longer than the bar's refresh on a busy machine (the first batch has its own line)
                new = bool(shapes) and (len(members), hw) not in shapes
                shapes.add((len(members), hw))
                with stage(f"running a new input shape, {len(members)} x {hw[0]} x {hw[1]} (a JAX predictor compiles "
                           f"for it)", enabled=progress and new):
                    found = run_stages(self.stages(members, hw))
                out.update(zip((item.image_id for item in members), found))
        return out

    def stages(self, images: Sequence[CameraImage], input_hw) -> Stages:
        """Images of one input shape -> their Boxes2D in image pixels, stage by stage (STAGES): what
        predict_samples runs and `dsfec bench` times."""
        def to_image(pair):
            found, affines = pair
            return [self.in_image(dets, affine, item.hw) for item, affine, dets in zip(images, affines, found)]

        return [("letterbox", lambda _: self.letterboxed(images, input_hw)), ("network_decode", carrying(self.decoded)),
                ("nms", carrying(lambda out: self.postprocess(*out))), ("to_image", to_image)]

    def in_image(self, dets: Boxes2D, affine: Affine, image_hw) -> Boxes2D:
        """Input-pixel detections -> the image's pixels (clipped), renamed by the class map."""
        xyxy = rescale(dets.xyxy, np.array([affine.sx, affine.sy]), np.array([affine.ox, affine.oy]), image_hw)
        keep = np.array([str(n) in self.class_map for n in dets.names], bool)
        names = np.array([self.class_map[str(n)] for n in dets.names[keep]], dtype="<U32")
        return dataclasses.replace(dets.select(keep), xyxy=xyxy[keep], names=names)


class CameraPredictor(InferenceVariables, CameraPipeline):
    """`predictor(image) -> Boxes2D` (original image pixels, scores) with the jitted JAX network."""

    def __init__(self, detector, variables, size: int = 416, rect: bool = True,
                 score_threshold: float = EVAL_SCORE, nms_iou: float = NMS_IOU,
                 max_detections: int = MAX_DETECTIONS, class_map: Mapping[str, str] | None = None,
                 constant_weights: bool = False):
        require_modality(detector.config, "image", "CameraPredictor")
        self.detector = self._inference_detector(detector)  # its inference form (modalities/inference.py)
        self.variables, self.constant_weights = variables, constant_weights
        self._setup(detector.name, detector.config.classes, size, rect, score_threshold, nms_iou, max_detections,
                    class_map)
        self.network = jax.jit(decoding_network(self.detector))

    def decoded(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        boxes, scores = self.call_network(images)
        return np.asarray(boxes), np.asarray(scores)

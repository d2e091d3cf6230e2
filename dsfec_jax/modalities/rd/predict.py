"""From range-Doppler maps to scored 2D boxes: representations (host, numpy) -> jitted network and
DFL decode -> class-aware NMS (host by default, models/yolo_rd/decode_host; or compiled into the same
graph, models/yolo_rd/decode.detect) -> boxes in map pixels (host).

Evaluation settings follow the paper (NMS IoU 0.1, after DAROD) and ultralytics' validator (conf
0.001, at most 300 boxes, multi-label); YOLOv10 decodes its one-to-one head without NMS.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from ..checks import require_modality
from ..inference import InferenceVariables
from ...core.progress import FIRST_BATCH, bar
from ...boxes.boxes2d import Boxes2D
from ...data.rd.batches import boxes_to_map, rd_eval_inputs
from ...data.rd.representations import RDRepresentation
from ...data.rd.sample import RDSample
from ...models.yolo_rd.decode import EVAL_CONF, EVAL_IOU, EVAL_MAX_DET, decode, detect
from ...models.yolo_rd.decode_host import NMS, TOP_K, host_detections
from ...models.yolo_rd.decode_v10 import detect_nms_free
from ...models.yolo_rd.net import inference_maps

OUTPUTS = ("boxes", "scores", "labels", "valid")  # what the compiled post-processing returns, per image


def detecting_network(detector, iou_threshold: float = EVAL_IOU, score_threshold: float = EVAL_CONF,
                      max_detections: int = EVAL_MAX_DET):
    """fn(variables, inputs) -> (boxes (B, K, 4) xyxy input pixels, scores (B, K), labels (B, K),
    valid (B, K)): the network, then its decode and NMS (what the predictor jits and export writes);
    YOLOv10 decodes its one-to-one head without NMS, as it is meant to run (`iou_threshold` unused)."""
    cfg = detector.config

    def run(variables, inputs):
        outputs = detector.apply(variables, inputs)
        if isinstance(outputs, dict):  # YOLOv10: its one-to-one head, top-k without NMS (decode_v10)
            return detect_nms_free(inference_maps(outputs), score_threshold, max_detections, cfg.strides, cfg.reg_max)
        return detect(outputs, iou_threshold, score_threshold, max_detections, cfg.strides, cfg.reg_max)

    return run


class RDPipeline:
    """What every runtime shares: representations on the host, the runtime's `run(inputs)` (network +
    decode + NMS), then boxes back to map pixels with class names. A subclass sets `classes`,
    `representation`, `input_names` and `run`."""

    classes: tuple[str, ...]
    representation: RDRepresentation
    input_names: tuple[str, ...]

    def run(self, inputs: dict) -> tuple[np.ndarray, ...]:
        raise NotImplementedError

    def __call__(self, sample: RDSample) -> Boxes2D:
        return self.predict_samples([sample])[sample.sample_id]

    def predict_samples(self, samples: Sequence[RDSample], batch_size: int = 8,
                        progress: bool = False) -> dict[str, Boxes2D]:
        """sample id -> detections (map pixels, scores), in batches of maps of one fitted size;
        `progress`: a bar over the batches on stderr (the commands' eval and predict)."""
        out = {}
        samples = [samples[i] for i in range(len(samples))]
        for start in bar(range(0, len(samples), batch_size), f"detecting in {len(samples)} maps", first=FIRST_BATCH,
                         enabled=progress, unit="batch"):
            chunk = [rd_eval_inputs(s, self.representation, self.classes) for s in samples[start:start + batch_size]]
            for group in _same_size(chunk):
                inputs = {k: np.concatenate([chunk[i][k] for i in group]) for k in self.input_names}
                boxes, scores, labels, valid = (np.asarray(a) for a in self.run(inputs))
                for j, i in enumerate(group):
                    sid = samples[start + i].sample_id
                    out[sid] = self._boxes(boxes[j], scores[j], labels[j], valid[j], chunk[i])
        return out

    def _boxes(self, boxes, scores, labels, valid, arrays: dict) -> Boxes2D:
        keep = np.flatnonzero(valid)
        xyxy = boxes_to_map(boxes[keep], arrays["to_map_scale"], arrays["map_hw"])
        names = np.array([self.classes[int(c)] for c in labels[keep]], dtype="<U16")
        return Boxes2D(xyxy.astype(np.float32), names, scores[keep].astype(np.float32))


def _same_size(chunk: list[dict]) -> list[list[int]]:
    """Indices of the chunk grouped by fitted input size (a batch needs one size)."""
    groups: dict[tuple, list[int]] = {}
    for i, arrays in enumerate(chunk):
        groups.setdefault(arrays["heat"].shape[1:3], []).append(i)
    return list(groups.values())


def decoding_network(detector):
    """fn(variables, inputs) -> (boxes (B, A, 4) xyxy input pixels, class scores (B, A, nc)): the
    network and the DFL decode (YOLOv10: of its one-to-one head), what the host post-processing reads."""
    cfg = detector.config
    return lambda variables, inputs: decode(inference_maps(detector.apply(variables, inputs)), cfg.strides, cfg.reg_max)


class RDPredictor(InferenceVariables, RDPipeline):
    """`predictor(sample) -> Boxes2D` (map pixels) with the jitted JAX network and decode, then the
    post-processing: on the host by default (models/yolo_rd/decode_host: faster once a trained model
    leaves few candidates above the confidence cut), or `postprocess="compiled"` in the same graph."""

    def __init__(self, detector, variables, representation: RDRepresentation = RDRepresentation(),
                 score_threshold: float = EVAL_CONF, nms_iou: float = EVAL_IOU, max_detections: int = EVAL_MAX_DET,
                 postprocess: str = "host"):
        require_modality(detector.config, "rd", "RDPredictor")
        if postprocess not in ("host", "compiled"):
            raise ValueError(f"RDPredictor postprocess={postprocess!r}; expected 'host' or 'compiled'")
        self.detector = self._inference_detector(detector)  # its inference form (modalities/inference.py)
        self.variables = variables
        self.classes, self.representation = tuple(detector.config.classes), representation
        self.input_names = detector.config.input_names
        self.score_threshold, self.nms_iou, self.max_detections = score_threshold, nms_iou, max_detections
        self.postprocess = postprocess
        self.kind = TOP_K if detector.config.arch == "v10" else NMS  # YOLOv10 runs NMS-free
        if postprocess == "compiled":
            self.network = jax.jit(detecting_network(self.detector, nms_iou, score_threshold, max_detections))
        else:
            self.network = jax.jit(decoding_network(self.detector))

    def run(self, inputs: dict):
        out = jax.device_get(self.network(self.variables, inputs))
        if self.postprocess == "compiled":
            return out
        boxes, scores = (np.asarray(a) for a in out)
        return host_detections(boxes, scores, self.kind, self.nms_iou, self.score_threshold, self.max_detections)

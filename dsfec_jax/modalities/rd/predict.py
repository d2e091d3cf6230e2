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
from ..stages import Stages, carrying, run as run_stages
from ...core.progress import FIRST_BATCH, bar
from ...boxes.boxes2d import Boxes2D
from ...data.rd.batches import boxes_to_map, rd_eval_inputs
from ...data.rd.representations import RDRepresentation, fitted_shape
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


STAGES = ("representation", "network_decode", "nms", "to_map")  # the predictor's path (`RDPipeline.stages`)


class RDPipeline:
    """What every runtime shares: representations on the host, the runtime's `decoded(inputs)`
    (network + decode), the host post-processing (class-aware NMS, or YOLOv10's top-k), then boxes
    back to map pixels with class names. A subclass sets `classes`, `representation`,
    `input_names`, `kind`, the thresholds and `decoded`."""

    classes: tuple[str, ...]
    representation: RDRepresentation
    input_names: tuple[str, ...]
    kind: str
    score_threshold: float
    nms_iou: float
    max_detections: int
    nms_on_host = True  # False: `decoded` already ran the post-processing (RDPredictor's compiled one)

    def decoded(self, inputs: dict) -> tuple[np.ndarray, ...]:
        """Fitted maps -> (boxes (B, A, 4) xyxy input pixels, class scores (B, A, nc)) as numpy."""
        raise NotImplementedError

    def postprocess(self, boxes, class_scores) -> tuple[np.ndarray, ...]:
        """Host post-processing (models/yolo_rd/decode_host) -> padded (boxes, scores, labels, valid)."""
        return host_detections(boxes, class_scores, self.kind, self.nms_iou, self.score_threshold, self.max_detections)

    def run(self, inputs: dict) -> tuple[np.ndarray, ...]:
        """Network + decode + NMS of fitted maps -> padded (boxes, scores, labels, valid)."""
        out = self.decoded(inputs)
        return self.postprocess(*out) if self.nms_on_host else out

    def __call__(self, sample: RDSample) -> Boxes2D:
        return self.predict_samples([sample])[sample.sample_id]

    def stages(self, samples: Sequence[RDSample]) -> Stages:
        """Samples of one fitted size -> their Boxes2D in map pixels, stage by stage (STAGES; with a
        compiled NMS 'network_decode_nms' in place of network_decode and nms): what predict_samples
        runs and `dsfec bench` times."""
        def represent(_):
            arrays = [rd_eval_inputs(s, self.representation, self.classes) for s in samples]
            return {k: np.concatenate([a[k] for a in arrays]) for k in self.input_names}, arrays

        def to_map(pair):
            (boxes, scores, labels, valid), arrays = pair
            return [self._boxes(boxes[j], scores[j], labels[j], valid[j], a) for j, a in enumerate(arrays)]

        if not self.nms_on_host:
            return [("representation", represent), ("network_decode_nms", carrying(self.decoded)), ("to_map", to_map)]
        return [("representation", represent), ("network_decode", carrying(self.decoded)),
                ("nms", carrying(lambda out: self.postprocess(*out))), ("to_map", to_map)]

    def predict_samples(self, samples: Sequence[RDSample], batch_size: int = 8,
                        progress: bool = False) -> dict[str, Boxes2D]:
        """sample id -> detections (map pixels, scores), in batches of maps of one fitted size;
        `progress`: a bar over the batches on stderr (the commands' eval and predict)."""
        out = {}
        samples = [samples[i] for i in range(len(samples))]
        for start in bar(range(0, len(samples), batch_size), f"detecting in {len(samples)} maps", first=FIRST_BATCH,
                         enabled=progress, unit="batch"):
            for group in _same_size(samples[start:start + batch_size], self.representation):
                out.update(zip((s.sample_id for s in group), run_stages(self.stages(group))))
        return out

    def _boxes(self, boxes, scores, labels, valid, arrays: dict) -> Boxes2D:
        keep = np.flatnonzero(np.asarray(valid))
        xyxy = boxes_to_map(np.asarray(boxes)[keep], arrays["to_map_scale"], arrays["map_hw"])
        names = np.array([self.classes[int(c)] for c in np.asarray(labels)[keep]], dtype="<U16")
        return Boxes2D(xyxy.astype(np.float32), names, np.asarray(scores)[keep].astype(np.float32))


def _same_size(samples: list[RDSample], representation: RDRepresentation) -> list[list[RDSample]]:
    """The samples grouped by fitted input size (a batch needs one size), in first-seen order."""
    groups: dict[tuple, list[RDSample]] = {}
    for s in samples:
        groups.setdefault(fitted_shape(s.shape, representation), []).append(s)
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
                 postprocess: str = "host", constant_weights: bool = False):
        require_modality(detector.config, "rd", "RDPredictor")
        if postprocess not in ("host", "compiled"):
            raise ValueError(f"RDPredictor postprocess={postprocess!r}; expected 'host' or 'compiled'")
        self.detector = self._inference_detector(detector)  # its inference form (modalities/inference.py)
        self.variables, self.constant_weights = variables, constant_weights
        self.classes, self.representation = tuple(detector.config.classes), representation
        self.input_names = detector.config.input_names
        self.score_threshold, self.nms_iou, self.max_detections = score_threshold, nms_iou, max_detections
        self.nms_on_host = postprocess == "host"
        self.kind = TOP_K if detector.config.arch == "v10" else NMS  # YOLOv10 runs NMS-free
        if postprocess == "compiled":
            self.network = jax.jit(detecting_network(self.detector, nms_iou, score_threshold, max_detections))
        else:
            self.network = jax.jit(decoding_network(self.detector))

    def decoded(self, inputs: dict):
        """The jitted network and decode (with `postprocess="compiled"` also the NMS), as numpy."""
        return tuple(np.asarray(a) for a in self.call_network(inputs))  # np.asarray: no device_get's pytree pass

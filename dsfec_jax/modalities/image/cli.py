"""The camera halves of `dsfec train | eval | predict | ship | export | quantize`: what the commands do
for a model whose family reads RGB images (Shuffle-YOLOv3, Darknet53-YOLOv3). cli.py parses the
flags, resolves the config once (--model, --set and `config_fields`: the classes) and hands it here
through the Modality record; the shared flags read:

- `--data street` (the family's embedded synthetic benchmark, also what `synthetic` means here),
  `street:DIR` (the same frames through a PNG/NPZ cache under DIR), `voc:DIR` (PASCAL VOC: a
  VOCdevkit year, or the 100 real VOC2012 images' folder with `--split all`). `--frames` counts
  images.
- Classes. `dsfec train` gives the model the data source's classes (the street benchmark's car,
  truck, bus, pedestrian, cyclist: `num_classes=5, class_names=(...)`, recorded in run.json's
  overrides) unless --set names them. `dsfec eval / predict` build the model with the classes of
  the run that made --weights (zoo.trained_fields: the manifest of shipped weights, or the run.json
  of the run directory a checkpoint sits in; --set wins); when those differ from the data's, detections are
  renamed into the data's classes (data/camera/sources.class_map: same name, or pedestrian <->
  person and cyclist <-> bicycle) and only the classes both know are scored.
- `--schedule quick|paper` is the family's profile (yolo3_quick / yolo3_paper, train/schedules.py)
  with its multi-scale sizes (modalities/image/fit.MULTI_SCALE); `--sizes LOW,HIGH` (or one size)
  overrides them. Validation, eval and predict letterbox each image to `--size` (416) on its long side.
- eval / predict keep detections down to darknet's mAP threshold (0.005) unless --score-threshold
  says otherwise; predict writes COCO JSON (results list, and with --gt-out the ground truth; image
  pixels) and with --png-dir one figure per image (ground truth solid, predictions scoring >= 0.25
  dashed with class and score; the best three when none does: modalities/pictures.py).
  `predict --input PATH...` reads a user's .jpg/.jpeg/.png files instead (modalities/image/files.py;
  the detections keep the model's class names) and writes one JSON entry per file.
- `dsfec export` writes the network and the YOLOv3 decode (modalities/image/export.py) at one letterboxed
  size: `--size S` the street frames' rectangle at long side S (default 416: 256 x 416), or
  `--input-hw H,W` any (multiples of 32; a square takes images of every shape, letterboxed as
  darknet does). The classes are those of the run that made --weights, as for eval.
- `dsfec eval / predict --runtime onnx --onnx DIR` run such an export (or its `dsfec quantize`
  INT8 copy) with ONNX Runtime; the letterbox and darknet's NMS run on the host as in the JAX
  predictor, the size is the export's (a different --size is refused) and --weights is not read.
- `dsfec quantize` calibrates on --calib-frames letterboxed street train images (seed --seed).
- the point-cloud flags (--window, --window-sampling, --max-pillars, export's --top-k) are refused,
  naming the flag.

This module never imports cli (the library's one-way door): cli passes what it parsed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ... import zoo
from ...core import progress
from ...models.camera.decode import EVAL_SCORE
from ...models.camera.family import FAMILY as CAMERA, class_fields
from .. import files
from ..cli_flags import LOADING, check_export_model, export_weights, onnx_predictor, refuse_point_flags, weights_or_exit
from ..pictures import planned
from .files import READER
from .predict import CameraPredictor

READS = "whole camera images"
EVAL_SIZE = 416  # eval / predict: the long side images are letterboxed to (the paper's 416)
TRAIN_FRAMES = 1000  # street frames generated for training without --frames (render rate: docs/camera.md)
CLASS_FIELDS = CAMERA.weight_fields  # num_classes, class_names: set from the training data
SYNONYMS = {"synthetic": "street"}  # the commands' default --data is the family's embedded benchmark


def data_source(args) -> str:
    return SYNONYMS.get(args.data, args.data)


def _images(args, split: str, count: int | None):
    """Images of --data, or exit with the source's message (it names --data and what was expected)."""
    from ...data.camera.sources import NoImages, load_camera_images

    try:
        return load_camera_images(data_source(args), split, count, args.seed)
    except (NoImages, ValueError, FileNotFoundError) as err:
        sys.exit(f"dsfec {args.command}: {err}")


def _source_classes(args) -> tuple[str, ...] | None:
    """The classes of --data; None for --input files (the detections keep the model's names)."""
    from ...data.camera.sources import source_classes

    if getattr(args, "input", None):
        return None

    try:
        return source_classes(data_source(args))
    except (ValueError, FileNotFoundError) as err:
        sys.exit(f"dsfec {args.command}: {err}")


def refuse(args, command: str) -> None:
    refuse_point_flags(args, READS)
    files.refuse_with_input(args)


def config_fields(args, overrides: dict) -> dict:
    """--set with the model's classes: for training, those of --data (with_data_classes); for
    the other commands, those of the run that made --weights (shipped weights: their manifest;
    a checkpoint: its run.json), --set first."""
    if args.command == "train":
        return with_data_classes(args, overrides)
    weights = Path(args.weights) if getattr(args, "weights", None) else zoo.shipped_weights(args.model)
    return {**zoo.trained_fields(weights, CLASS_FIELDS), **overrides}


def with_data_classes(args, overrides: dict) -> dict:
    """The model's classes for training on --data: the source's, unless --set names them."""
    if any(f in overrides for f in CLASS_FIELDS):
        return overrides
    return {**overrides, **class_fields(_source_classes(args))}


def eval_size(args) -> int:
    """--size (default EVAL_SIZE), or exit when it is not a multiple of the networks' stride 32."""
    size = args.size or EVAL_SIZE
    if size % 32:
        sys.exit(f"dsfec {args.command}: --size {size}: expected a multiple of 32")
    return size


def parse_sizes(text: str | None):
    """--sizes LOW,HIGH (every multiple of 32 between) or SIZE -> MultiScale; None: the profile's."""
    from ...data.camera.batches import MultiScale

    if text is None:
        return None
    try:
        bounds = [int(v) for v in text.split(",")]
        if len(bounds) not in (1, 2):
            raise ValueError(text)
        return MultiScale.span(bounds[0], bounds[-1]) if len(bounds) == 2 else MultiScale((bounds[0],))
    except ValueError as err:
        sys.exit(f"--sizes {text!r}: expected LOW,HIGH or SIZE, multiples of 32 ({err})")


def train(args, cfg, overrides: dict, schedule, info: dict) -> dict:
    """`dsfec train` of a camera model: fit_camera on the images of --data."""
    from .fit import fit_camera
    from ...train.loop import RunMismatch

    sizes, size = parse_sizes(args.sizes), eval_size(args)
    images = _images(args, args.split, args.frames or TRAIN_FRAMES)
    val = _images(args, "val", args.val_frames)
    try:
        _, _, final = fit_camera(cfg, images, val, schedule, args.run_dir, args.seed, args.steps, not args.no_augment,
                                 args.eval_every, info, overrides=overrides, sizes=sizes, eval_size=size)
    except (RunMismatch, ValueError) as err:  # another setup in the run directory; classes the model lacks
        sys.exit(f"dsfec train: {err}")
    return final


def _onnx_predictor(args, score_threshold: float):
    """OrtCameraPredictor of --onnx, renaming the export's classes into --data's."""
    from ...data.camera.sources import class_map
    from ...deploy.ort import read_manifest
    from .ort import OrtCameraPredictor

    def make(export_dir):  # the model is checked before its classes are mapped into --data's
        _, manifest = read_manifest(export_dir, "image")
        check_export_model(args, manifest)
        data_classes = _source_classes(args)
        return OrtCameraPredictor(export_dir, score_threshold=score_threshold,
                                  class_map=None if data_classes is None else class_map(manifest["classes"], data_classes))

    predictor = onnx_predictor(args, make)  # also exits on no shared class (a ValueError)
    if args.size is not None and args.size != predictor.size:
        sys.exit(f"dsfec {args.command}: --size {args.size}: the export {args.onnx} takes images letterboxed to "
                 f"{predictor.size} (its input {tuple(predictor.manifest['input_hw'])}); drop --size or export again")
    return predictor


def _predictor(args, cfg, score_threshold: float):
    """CameraPredictor of --weights with the config's classes (config_fields: the weights' run's)
    renamed into --data's."""
    from ...data.camera.sources import class_map

    data_classes = _source_classes(args)
    try:
        mapping = None if data_classes is None else class_map(cfg.classes, data_classes)
    except (TypeError, ValueError) as err:
        sys.exit(f"dsfec {args.command}: {err}")
    with progress.doing(LOADING.format(cfg.name)):
        detector, variables = weights_or_exit(args, cfg)
        return CameraPredictor(detector, variables, score_threshold=score_threshold, size=eval_size(args),
                               class_map=mapping, constant_weights=True)


def eval_or_predict(args, cfg) -> tuple:
    """`dsfec eval` / `dsfec predict` of a camera model -> (images, detections, predictor, extra
    report fields); the protocol: VOC mAP@0.5 (VOC07 and all-point) and COCO AP."""
    from ...data.camera.voc import UnreadableImage

    eval_size(args)
    threshold = EVAL_SCORE if args.score_threshold is None else args.score_threshold
    # a bad --data fails before any network is compiled; a bad --onnx (read, not compiled) before images are made
    onnx = _onnx_predictor(args, threshold) if args.runtime == "onnx" else None
    images = files.items_or_exit(args, READER, cfg) if getattr(args, "input", None) else \
        _images(args, args.split, args.frames)
    predictor = onnx or _predictor(args, cfg, threshold)
    try:  # images are decoded as the loop reaches them
        detections = predictor.predict_samples(images, progress=True)
        if args.command == "predict":
            write_predictions(args, images, detections, predictor)
    except UnreadableImage as err:
        sys.exit(f"dsfec {args.command}: {err}")
    return images, detections, predictor, {"score_threshold": threshold, "classes_scored": list(predictor.classes)}


def write_predictions(args, images, detections: dict, predictor) -> None:
    """--out: the COCO results list (image pixels; category ids 1..C in the predictor's class order);
    --gt-out: the scored ground truth with the same ids (difficult as iscrowd); --png-dir: PNGs."""
    from ...core import atomic
    from .evaluate import ground_truth
    from ...metrics.boxes2d.coco_json import coco_dets_to_list, default_category_ids, default_image_ids
    from ...metrics.boxes2d.voc_coco import voc_gt_to_coco

    if getattr(args, "input", None):  # a user's files: one entry per file (modalities/files.py)
        files.write_document(args, READER, images, detections, score_threshold=predictor.score_threshold)
        write_pngs(args, images, detections, predictor)
        return
    ids = [images[i].image_id for i in range(len(images))]
    image_ids, category_ids = default_image_ids(ids), default_category_ids(predictor.classes)
    atomic.write_json(args.out, coco_dets_to_list(detections, category_ids, image_ids))
    if args.gt_out:
        atomic.write_json(args.gt_out, voc_gt_to_coco(ground_truth(images, predictor.classes)[0], predictor.classes))
    write_pngs(args, images, detections, predictor)


def write_pngs(args, images, detections: dict, predictor) -> None:
    """--png-dir: a figure per image (data/camera/figure): ground truth, and the detections scoring
    >= --png-min-score (default pictures.PNG_MIN_SCORE; when none does, the best few: modalities/pictures)."""
    from ...data.camera.figure import save_camera_figure

    for item, found, keep, path, title in planned(args, images, detections, READER.ident):
        save_camera_figure(item, path, found.select(keep), predictor.classes, title)


def ship_predictor(cfg, source: Path, info: dict):
    """(CameraPredictor at the evaluation settings, variables) of a run's checkpoint, built with the
    run's config and evaluation size."""
    det = zoo.Detector(cfg)
    variables = zoo.model_variables(det, source)
    return CameraPredictor(det, variables, size=info.get("eval_size", 416)), variables


def export_input_hw(args) -> tuple[int, int]:
    """The letterboxed (H, W) to export: --input-hw, else the street frames' rectangle at --size
    (default EVAL_SIZE: 256 x 416); exit when both are given or a side is not a multiple of 32."""
    from .export import check_input_hw, street_input_hw

    if args.input_hw and args.size:
        sys.exit("dsfec export: give --size (the street frames' rectangle at that long side) or --input-hw H,W, "
                 "not both")
    if not args.input_hw:
        return street_input_hw(eval_size(args))
    try:
        return check_input_hw([int(v) for v in args.input_hw.split(",")])
    except ValueError as err:
        sys.exit(f"dsfec export: --input-hw {args.input_hw!r}: {err}")


def export(args, cfg, command: str) -> dict:
    """`dsfec export` of a camera model: export_camera (network + YOLOv3 decode; ONNX and
    jax.export) with the classes of the run that made --weights (config_fields)."""
    from .export import export_camera

    input_hw = export_input_hw(args)
    path = export_weights(args)
    det = zoo.Detector(cfg)
    variables = zoo.model_variables(det, path)
    return export_camera(det, variables, args.out, source={"weights": str(path), "command": command},
                         input_hw=input_hw)


def quantize(args) -> dict:
    """`dsfec quantize` of a camera export: static INT8 calibrated on letterboxed street train images."""
    from ...data.camera.sources import load_camera_images
    from .quantize import quantize_camera

    try:
        return quantize_camera(args.onnx, args.out, load_camera_images("street", "train", args.calib_frames, args.seed),
                               calibration=args.calibration)
    except ValueError as err:  # an export that takes other images than the street frames' rectangle
        sys.exit(f"dsfec quantize: {err}")

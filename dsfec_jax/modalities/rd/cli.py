"""The range-Doppler halves of `dsfec train | eval | predict | ship | export | quantize`: what the
commands do for a model whose family reads RD maps (the YOLO-RD family). cli.py parses the flags,
resolves the config once (--model, --set) and hands it here through the Modality record; the flags
mean the same for every family, with these readings for RD models:

- `--data synthetic` (the default) is the embedded RD benchmark (data/rd/synthetic); `raddet:PATH`
  and `carrada:PATH` read real maps. `--frames` counts RD samples.
- `--schedule quick|paper` is the family's profile (Family.schedules: yolo_quick / yolo_paper, the
  ultralytics recipe); any train.schedules preset name is accepted as well.
- train without --frames: TRAIN_SAMPLES synthetic samples, what yolo_quick is sized for (a real
  source: its whole split).
- eval / predict keep detections down to the paper's evaluation confidence (decode.EVAL_CONF,
  0.001) unless --score-threshold says otherwise; predict writes COCO JSON (results list and
  ground truth, map-pixel boxes) and with --png-dir one figure per sample with its ground truth and
  predictions. `predict --input PATH...` reads a user's .npy maps and raw TI ADC captures instead
  (modalities/rd/files.py) and writes one JSON entry per file.
- the point-cloud flags (--window, --window-sampling, --max-pillars, export's --top-k) and the
  camera ones (--size, --sizes) do not apply to whole RD maps: given explicitly they are refused,
  naming the flag, rather than ignored.

This module never imports cli (the library's one-way door): cli passes what it parsed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ... import zoo
from ...core import progress
from ...models.yolo_rd.decode import EVAL_CONF
from .. import files
from ..cli_flags import LOADING, export_weights, onnx_predictor, refuse_camera_flags, refuse_point_flags, weights_or_exit
from ..pictures import planned
from .files import READER
from .predict import RDPredictor

# yolo_quick (train/schedules.py) is "15 epochs over ~1000 synthetic 256x64 samples": 62 batches of
# 16 an epoch, the 14,880 training frames its CPU timing assumes
TRAIN_SAMPLES = 1000
READS = "whole range-Doppler maps"


def refuse(args, command: str) -> None:
    refuse_camera_flags(args, command, "rd")
    refuse_point_flags(args, READS)
    files.refuse_with_input(args)


def config_fields(args, overrides: dict) -> dict:
    return overrides  # no flag or data source sets a field of an RD model's config


def default_train_samples(data: str) -> int | None:
    """Samples to train on when --frames is not given: TRAIN_SAMPLES generated ones for the
    synthetic benchmark, the whole split (None) of a real source."""
    return TRAIN_SAMPLES if data.partition(":")[0] in ("synthetic", "rd-synthetic") else None


def _samples(args, split: str, count: int | None, data: str | None = None) -> list:
    """RD samples of --data (or `data`), or exit with the source's message (it names --data and
    what was expected)."""
    from ...data.rd.sources import NoSamples, load_rd_samples

    try:
        return load_rd_samples(data or args.data, split, count, args.seed)
    except (NoSamples, ValueError, FileNotFoundError) as err:
        sys.exit(f"dsfec {args.command}: {err}")


def train(args, cfg, overrides: dict, schedule, info: dict) -> dict:
    """`dsfec train` of an RD model: fit_rd on RD samples."""
    from ...train.loop import RunMismatch
    from .fit import fit_rd

    samples = _samples(args, args.split, args.frames or default_train_samples(args.data))
    val = _samples(args, "val", args.val_frames)
    try:
        _, _, final = fit_rd(cfg, samples, val, schedule, args.run_dir, args.seed, args.steps, not args.no_augment,
                             args.eval_every, info, overrides=overrides)
    except RunMismatch as err:  # a run directory started with another setup: the user's to fix
        sys.exit(f"dsfec train: {err}")
    return final


def _predictor(args, cfg, score_threshold: float):
    if args.runtime == "onnx":
        from .ort import OrtRDPredictor

        return onnx_predictor(args, lambda export_dir: OrtRDPredictor(export_dir, score_threshold=score_threshold))
    with progress.doing(LOADING.format(cfg.name)):
        detector, variables = weights_or_exit(args, cfg)
        return RDPredictor(detector, variables, score_threshold=score_threshold, constant_weights=True)


def eval_or_predict(args, cfg) -> tuple:
    """`dsfec eval` / `dsfec predict` of an RD model -> (samples, detections, predictor, extra
    report fields); the protocol: COCO mAP@50, @50-95, @30 and DAROD mAP@50."""
    threshold = EVAL_CONF if args.score_threshold is None else args.score_threshold
    # a bad --data or --input file fails before any network is built
    samples = files.items_or_exit(args, READER, cfg) if getattr(args, "input", None) else \
        _samples(args, args.split, args.frames)
    predictor = _predictor(args, cfg, threshold)
    detections = predictor.predict_samples(samples, progress=True)
    if args.command == "predict":
        write_predictions(args, samples, detections, predictor)
    return samples, detections, predictor, {"score_threshold": threshold}


def write_predictions(args, samples, detections: dict, predictor) -> None:
    """--out: the COCO results list (map pixels; image ids from the sample ids, category ids 1..C in
    the model's class order: metrics/boxes2d/coco_json defaults); --gt-out: the ground truth as a
    COCO object with the same ids, so the pair scores offline; --png-dir: one PNG per sample."""
    from ...core import atomic
    from .evaluate import ground_truth
    from ...metrics.boxes2d.coco_json import coco_dets_to_list, coco_gt_to_dict, default_category_ids, default_image_ids

    if getattr(args, "input", None):  # a user's files: one entry per file (modalities/files.py)
        files.write_document(args, READER, samples, detections, score_threshold=predictor.score_threshold)
        write_pngs(args, samples, detections, predictor)
        return
    image_ids = default_image_ids([s.sample_id for s in samples])
    category_ids = default_category_ids(predictor.classes)
    try:
        results = coco_dets_to_list(detections, category_ids, image_ids)
        gt = coco_gt_to_dict(ground_truth(samples), predictor.classes, image_ids=image_ids,
                             category_ids=category_ids) if args.gt_out else None
    except ValueError as err:  # e.g. a source labelling a class the model does not know
        sys.exit(f"dsfec predict: {err}")
    atomic.write_json(args.out, results)
    if gt is not None:
        atomic.write_json(args.gt_out, gt)
    write_pngs(args, samples, detections, predictor)


def write_pngs(args, samples, detections: dict, predictor) -> None:
    """--png-dir: a figure per sample (data/rd/figure: range in m, velocity in m/s, colorbar, ground
    truth and the detections scoring >= --png-min-score (default pictures.PNG_MIN_SCORE))."""
    from ...data.rd.figure import save_rd_figure

    representation = getattr(predictor, "representation", None)
    colormap = representation.colormap if representation is not None else "viridis"
    for sample, found, keep, path, title in planned(args, samples, detections, READER.ident):
        save_rd_figure(sample, path, found.select(keep), predictor.classes, colormap, title)


def _representation(info: dict):
    """The representation a training run used (run.json), so shipping measures what it trained."""
    from ...data.rd.representations import RDRepresentation

    fields = dict(info.get("representation") or {})
    if fields.get("input_hw") is not None:
        fields["input_hw"] = tuple(fields["input_hw"])
    return RDRepresentation(**fields)


def ship_predictor(cfg, source: Path, info: dict):
    """(RDPredictor at the evaluation settings, variables) of a run's checkpoint, built with the
    run's config and representation."""
    det = zoo.Detector(cfg)
    variables = zoo.model_variables(det, source)
    return RDPredictor(det, variables, _representation(info)), variables


def parse_hw(text: str) -> tuple[int, int]:
    try:
        hw = tuple(int(v) for v in text.split(","))
    except ValueError:
        hw = ()
    if len(hw) != 2 or min(hw) < 1:
        sys.exit(f"--input-hw {text!r}: expected HEIGHT,WIDTH in map cells, e.g. 256,64")
    return hw


def export(args, cfg, command: str) -> dict:
    """`dsfec export` of an RD model: export_rd (network, DFL decode; ONNX and jax.export)."""
    from .export import export_rd

    size = {"input_hw": parse_hw(args.input_hw)} if args.input_hw else {}
    path = export_weights(args)
    det = zoo.Detector(cfg)
    variables = zoo.model_variables(det, path)
    return export_rd(det, variables, args.out, source={"weights": str(path), "command": command}, **size)


def quantize(args) -> dict:
    """`dsfec quantize` of an RD export: static INT8 calibrated on synthetic RD train samples."""
    from .quantize import quantize_rd

    samples = _samples(args, "train", args.calib_frames, data="synthetic")
    return quantize_rd(args.onnx, args.out, samples, calibration=args.calibration)

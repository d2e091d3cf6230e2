"""The point-cloud halves of `dsfec train | eval | predict | ship | export | quantize`: what the
commands do for a model whose family reads radar points (DSFEC, RadarNeXt). cli.py parses the
flags, resolves the config once and hands it here through the Modality record; the shared flags read:

- `--data synthetic` (the default) is the family's embedded benchmark (data/points/synthetic);
  `synthetic4d`, `vod:PATH`, `tj4d:PATH` and `nuscenes:DATAROOT` read other sources. `--frames`
  counts frames.
- `--max-pillars` sets the pillar slots (default RUN_PILLARS), `--window` / `--window-sampling`
  the training windows (default 96 cells, cycled); `--size`, `--sizes` (camera) and `--input-hw`
  (range-Doppler, camera) are refused, naming the flag.
- eval / predict keep detections scoring at least POINT_SCORE_THRESHOLD (core/defaults) unless --score-threshold says
  otherwise; predict writes a nuScenes submission JSON (and with --gt-out the ground truth on the
  model's grid) and with --png-dir a BEV figure per frame (metres, legend, class scores).
  `predict --input PATH...` reads a user's .pcd / .bin files instead (modalities/points/files.py;
  `--columns` for a .bin) and writes one JSON entry per file.
- `dsfec quantize` calibrates on --calib-frames synthetic train frames (seed --seed).

This module never imports cli (the library's one-way door): cli passes what it parsed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ... import zoo
from ...core import progress
from ...core.defaults import POINT_SCORE_THRESHOLD, RUN_PILLARS
from .. import files
from ..cli_flags import LOADING, export_weights, onnx_predictor, refuse_camera_flags
from ..pictures import planned
from .files import READER
from .predict import Predictor

TRAIN_WINDOW = 96  # training-window cells without --window (0: the whole grid)


def refuse(args, command: str) -> None:
    refuse_camera_flags(args, command, "points")
    files.refuse_with_input(args)
    if command == "export" and args.input_hw:
        sys.exit(f"dsfec export: --input-hw applies to range-Doppler models; {args.model!r} reads point clouds")


def config_fields(args, overrides: dict) -> dict:
    """--set with the pillar slots of --max-pillars (default RUN_PILLARS; --set max_pillars wins)."""
    return {"max_pillars": args.max_pillars or RUN_PILLARS, **overrides}


def _frames(args, cfg, split: str, count: int | None):
    from ...data.points.sources import load_frames

    return load_frames(args.data, split, count, args.seed, features=zoo.family_of(cfg).points.input_columns)


def train(args, cfg, overrides: dict, schedule, info: dict) -> dict:
    """`dsfec train` of a point model: fit on frames of --data, in training windows."""
    from ...data.points.sources import NoFrames
    from ...train.loop import RunMismatch
    from .fit import fit

    window = TRAIN_WINDOW if args.window is None else args.window
    try:  # an empty split, or a run directory started with another setup: the user's to fix
        frames = _frames(args, cfg, args.split, args.frames or (schedule.batch_size * 100))
        val = _frames(args, cfg, "val", args.val_frames)
        _, _, final = fit(cfg, frames, val, schedule, args.run_dir, args.seed, args.steps, not args.no_augment,
                          args.eval_every, info, overrides=overrides, window=window or None,
                          window_sampling=args.window_sampling or "cycle")
    except (NoFrames, RunMismatch) as err:
        sys.exit(f"dsfec train: {err}")
    return final


def _predictor(args, cfg, threshold: float):
    if args.runtime == "onnx":
        from .ort import OrtPredictor

        return onnx_predictor(args, lambda export_dir: OrtPredictor(export_dir, score_threshold=threshold))
    with progress.doing(LOADING.format(cfg.name)):
        try:
            detector, variables = zoo.trained_detector(cfg, args.weights)
        except FileNotFoundError as err:
            sys.exit(f"dsfec {args.command}: {err} (--weights)")
        return Predictor(detector, variables, score_threshold=threshold, constant_weights=True)


def eval_or_predict(args, cfg) -> tuple:
    """`dsfec eval` / `dsfec predict` of a point model -> (frames, detections, predictor, {})."""
    from ...data.points.sources import NoFrames

    threshold = POINT_SCORE_THRESHOLD if args.score_threshold is None else args.score_threshold
    if getattr(args, "input", None):  # a user's files: every one read and checked before the model is built
        frames = files.items_or_exit(args, READER, cfg)
    predictor = _predictor(args, cfg, threshold)
    if not getattr(args, "input", None):
        try:
            frames = _frames(args, cfg, args.split, args.frames)
        except NoFrames as err:
            sys.exit(f"dsfec {args.command}: {err}")
    detections = predictor.predict_samples(frames, progress=True)
    if args.command == "predict":
        write_predictions(args, frames, detections, predictor)
    return frames, detections, predictor, {"score_threshold": threshold}


def write_predictions(args, frames, detections: dict, predictor) -> None:
    """--out: the nuScenes submission (--input: one entry per file, modalities/files.py); --gt-out:
    the frames' ground truth on the model's grid (what the metric scores); --png-dir: a BEV figure
    per frame."""
    from ...metrics.submission import boxes_to_entries, write_submission
    from .evaluate import in_grid

    if getattr(args, "input", None):
        files.write_document(args, READER, frames, detections, score_threshold=predictor.score_threshold)
        write_pngs(args, frames, detections, predictor)
        return
    results = {token: boxes_to_entries(token, d.boxes, d.scores) for token, d in detections.items()}
    write_submission(args.out, results)
    if args.gt_out:
        grid = predictor.spec.grid  # the boxes the metric scores: those on the model's grid
        gt = {f.frame_id: boxes_to_entries(f.frame_id, in_grid(f.boxes, grid)) for f in (frames[i] for i in range(len(frames)))}
        write_submission(args.gt_out, gt, is_gt=True)
    write_pngs(args, frames, detections, predictor)


def write_pngs(args, frames, detections: dict, predictor) -> None:
    """--png-dir: a BEV figure per frame (data/points/bev_figure), its detections at least
    --png-min-score (default pictures.PNG_MIN_SCORE, or the best few when none reaches it)."""
    from ...data.points.bev_figure import save_bev_figure

    for frame, found, keep, path, title in planned(args, frames, detections, READER.ident):
        save_bev_figure(frame, path, predictor.spec.grid, found.boxes.select(keep), found.scores[keep],
                        predictor.class_names, title)


def ship_predictor(cfg, source: Path, info: dict):
    """(Predictor at the evaluation settings, variables) of a run's checkpoint."""
    import dataclasses

    # measure with the pillar slots the run validated with (RadarNeXt runs set their own)
    if "max_pillars" not in info.get("overrides", {}):
        cfg = dataclasses.replace(cfg, max_pillars=RUN_PILLARS)
    detector = zoo.Detector(cfg)
    variables = zoo.model_variables(detector, source)
    return Predictor(detector, variables, score_threshold=POINT_SCORE_THRESHOLD), variables


def export(args, cfg, command: str) -> dict:
    """`dsfec export` of a point model: deploy.export (network and per-head top-k decode; ONNX and jax.export)."""
    from .export import export as export_points

    path = export_weights(args)
    detector = zoo.Detector(cfg)
    variables = zoo.model_variables(detector, path)
    return export_points(detector, variables, args.out, top_k=args.top_k or 100,
                         source={"weights": str(path), "command": command})


def quantize(args) -> dict:
    """`dsfec quantize` of a point export: static INT8 calibrated on synthetic train frames."""
    from ...data.points.sources import load_frames
    from .quantize import quantize as quantize_points

    return quantize_points(args.onnx, args.out, load_frames("synthetic", "train", args.calib_frames, args.seed),
                           calibration=args.calibration)

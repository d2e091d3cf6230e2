"""What the modalities' command halves share: the flags that belong to one modality (the others
refuse them, naming the flag, rather than ignore them) and the readings of --onnx, --weights as
eval, predict and export take them. The modalities' cli modules never import dsfec_jax.cli (the
library's one-way door)."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import zoo
from ..core.run_checkpoints import readable

# the phase a predictor's construction runs in (the watchdog's words for it on a slow start)
LOADING = "loading {}: its weights onto the device, BatchNorm folded into the convs"

# flags of the point-cloud pipeline (pillars, BEV windows, per-head top-k): attribute -> flag
POINT_FLAGS = {"window": "--window", "window_sampling": "--window-sampling", "max_pillars": "--max-pillars",
               "top_k": "--top-k"}


def refuse_point_flags(args, reads: str) -> None:
    """Exit naming every point-cloud flag the user gave to a model that `reads` something else (an
    RD model, a camera model; the flags' defaults are None)."""
    given = [flag for attr, flag in POINT_FLAGS.items() if getattr(args, attr, None) is not None]
    if given:
        sys.exit(f"dsfec {args.command}: {', '.join(given)} "
                 f"{'applies' if len(given) == 1 else 'apply'} to point-cloud models (pillars, BEV windows); "
                 f"{args.model!r} reads {reads}: drop {'it' if len(given) == 1 else 'them'}")


def refuse_camera_flags(args, command: str, modality: str) -> None:
    """Exit when --size (or train's --sizes) is given to a model of `modality`, not a camera one."""
    if command == "train" and (args.sizes or args.size):
        sys.exit(f"dsfec train: --sizes and --size apply to camera models; {args.model!r} is a {modality!r} model")
    if command != "train" and getattr(args, "size", None):
        sys.exit(f"dsfec {command}: --size applies to camera models; {args.model!r} is not one")


def export_weights(args) -> Path:
    """The weights `dsfec export` reads: --weights, else the model's shipped weights; exit when absent."""
    path = Path(args.weights) if args.weights else zoo.shipped_weights(args.model)
    if not readable(path):
        sys.exit(f"no weights at {path}: pass --weights (a trained checkpoint or weights file)")
    return path


def onnx_predictor(args, make):
    """make(export_dir) -> the ONNX Runtime predictor of --onnx; exit when --onnx is missing, holds no
    export (or another modality's) or another model's."""
    if not args.onnx:
        sys.exit("--runtime onnx needs --onnx DIR (written by `dsfec export --model NAME --out DIR`)")
    try:
        predictor = make(args.onnx)
    except (FileNotFoundError, ValueError) as err:  # no export there, or another modality's
        sys.exit(f"dsfec {args.command}: --onnx {err}")
    check_export_model(args, predictor.manifest)
    return predictor


def check_export_model(args, manifest: dict) -> None:
    if manifest["model"] != args.model:
        sys.exit(f"{args.onnx}: holds {manifest['model']!r}, not --model {args.model!r}")


def weights_or_exit(args, cfg) -> tuple:
    """(detector, variables) of `cfg` from --weights (default: the shipped weights); exit naming --weights."""
    try:
        return zoo.trained_detector(cfg, args.weights)
    except FileNotFoundError as err:
        sys.exit(f"dsfec {args.command}: {err}" + ("" if "--weights" in str(err) else " (--weights)"))

"""What `dsfec eval` / `dsfec predict` print for every family: the run's facts and the family's
protocol scores (evaluate.report), as JSON or one line. Shared by cli.py and cli_rd.py (which
never imports cli)."""

from __future__ import annotations

import json

from . import zoo
from .modalities.points.evaluate import report


def print_scores(args, items, detections: dict, predictor, noun: str, **extra) -> int:
    """Score `detections` of `items` (frames or RD samples, named `noun` in the line) and print."""
    weights = str(args.onnx if args.runtime == "onnx" else args.weights or zoo.shipped_weights(args.model))
    result = {"model": args.model, "runtime": args.runtime, "weights": weights, "data": args.data,
              "split": args.split, "seed": args.seed, "frames": len(items), **extra}
    scored, summary = report(zoo.family_of(args.model).metric.name, items, detections, predictor)
    result.update(scored)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"{args.model} on {args.data}/{args.split} ({len(items)} {noun}): {summary}")
    return 0


def predict_and_report(args, items, predictor, detect, write, noun: str, **extra) -> int:
    """`dsfec eval` / `dsfec predict` once the items and the predictor are made: `detect(items)` ->
    detections, `write(args, items, detections, predictor)` for predict, then the scores printed."""
    detections = detect(items)
    if args.command == "predict":
        write(args, items, detections, predictor)
    return print_scores(args, items, detections, predictor, noun, **extra)

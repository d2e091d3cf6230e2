"""What `dsfec eval` / `dsfec predict` print for every family: the run's facts and the family's
protocol scores (the Protocol's report, modalities/registry.protocol), as JSON or one line."""

from __future__ import annotations

import json

from . import zoo
from .modalities.registry import protocol


def print_scores(args, items, detections: dict, predictor, noun: str, **extra) -> int:
    """Score `detections` of `items` (frames, RD samples or images, named `noun` in the line) and print."""
    weights = str(args.onnx if args.runtime == "onnx" else args.weights or zoo.shipped_weights(args.model))
    result = {"model": args.model, "runtime": args.runtime, "weights": weights, "data": args.data,
              "split": args.split, "seed": args.seed, "frames": len(items), **extra}
    scored, summary = protocol(zoo.family_of(args.model).metric.name).report(items, detections, predictor)
    result.update(scored)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"{args.model} on {args.data}/{args.split} ({len(items)} {noun}): {summary}")
    return 0

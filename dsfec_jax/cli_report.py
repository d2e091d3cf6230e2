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



def print_found(args, modality, items, detections: dict, **extra) -> int:
    """What `dsfec predict --input` found (no ground truth, so no score): files, detections per
    class, where the JSON and the figures went."""
    from .modalities.files import detections_document

    weights = str(args.onnx if args.runtime == "onnx" else args.weights or zoo.shipped_weights(args.model))
    document = detections_document(args.model, modality.files, items, detections)
    names = [d["class"] for entry in document["inputs"] for d in entry["detections"]]
    per_class = {c: names.count(c) for c in sorted(set(names))}
    result = {"model": args.model, "runtime": args.runtime, "weights": weights, "inputs": len(items),
              "detections": len(names), "per_class": per_class, "out": str(args.out), "png_dir": args.png_dir, **extra}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        classes = ", ".join(f"{c} {k}" for c, k in per_class.items()) or "none"
        print(f"{args.model} on {len(items)} {modality.noun}s of --input: {len(names)} detections ({classes}); "
              f"wrote {args.out}" + (f" and figures in {args.png_dir}" if args.png_dir else ""))
    return 0

"""What the 100 real VOC2012 images say about a street-trained camera detector, and what a fine-tune
on part of them shows (issue 24: they are too few to train on).

    python -m experiments.camera_voc_finetune [--weights W] [--voc DIR] [--tune-images 50] [--steps 150] [--out DIR]

The images are split by sorted image id: the first `--tune-images` tune, the rest are held out and
are the only ones scored. Three rows, all on the held-out images at the classes the street
benchmark and VOC share (car, bus, pedestrian -> person, cyclist -> bicycle; data/camera/sources):
1. zero-shot: the street weights as shipped;
2. BN adapted: the same weights with their BN statistics re-estimated on the tune images (no
   gradient step; modalities/image/fit.bn_recalibration), which separates the image-statistics gap of
   synthetic -> real from what the weights learnt;
3. fine-tuned: every weight trained `--steps` steps on the tune images (their VOC labels renamed to
   the model's classes, boxes of other VOC classes left out: background to the model), quick
   recipe at a lower rate (AdamW `--lr`, 416 x 416 letterbox, darknet's augmentations), BN
   re-estimated on the tune images before scoring as every camera validation does.
Writes table.md and finetune.json (rows, split ids, command, seed, versions) atomically into --out;
the fine-tune run directory is resumable (its end-of-run validation, on one batch of tune images,
is not used: the rows are scored here).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from dsfec_jax import zoo
from dsfec_jax.core import atomic
from dsfec_jax.core.provenance import versions
from dsfec_jax.data.camera.batches import MultiScale
from dsfec_jax.data.camera.images import CameraImage
from dsfec_jax.data.camera.sources import class_map, load_camera_images, source_classes
from dsfec_jax.modalities.image.evaluate import evaluate_camera
from dsfec_jax.models.camera.family import FAMILY as CAMERA
from dsfec_jax.modalities.image.fit import bn_recalibration, fit_camera
from dsfec_jax.modalities.image.predict import CameraPredictor
from dsfec_jax.train.schedules import get_schedule

from experiments.common import fmt

MODEL = "shuffle_yolov3"
VOC_DIR = Path("../shared/data/voc_review_od_metrics/data/database")
EVAL_SIZE = 416  # the long side images are letterboxed to (the paper's 416)
HEADLINE = ("mAP50", "mAP50_all", "coco_mAP50_95")


def split_by_id(images, tune_count: int) -> tuple[list[CameraImage], list[CameraImage]]:
    """(tune, held out): the first `tune_count` images by sorted id, and the rest."""
    ordered = sorted((images[i] for i in range(len(images))), key=lambda item: item.image_id)
    if not 0 < tune_count < len(ordered):
        raise ValueError(f"--tune-images {tune_count}: expected 1..{len(ordered) - 1} ({len(ordered)} images)")
    return ordered[:tune_count], ordered[tune_count:]


def renamed(images: list[CameraImage], data_to_model: dict[str, str]) -> list[CameraImage]:
    """The images with their boxes renamed into the model's classes; boxes of other classes dropped."""
    out = []
    for item in images:
        keep = np.isin(item.boxes.names, list(data_to_model))
        boxes = item.boxes.select(keep)
        names = np.array([data_to_model[str(n)] for n in boxes.names], dtype="<U32")
        out.append(dataclasses.replace(item, boxes=dataclasses.replace(boxes, names=names)))
    return out


def held_out_scores(predictor: CameraPredictor, variables: dict, held_out: list[CameraImage]) -> dict:
    predictor.variables = variables  # one jitted network scores every row
    return evaluate_camera(predictor, held_out)[0]


def fine_tune(det, overrides: dict, variables: dict, tune: list[CameraImage], args) -> dict:
    """Variables after `args.steps` steps on the tune images (BN re-estimated on them)."""
    schedule = get_schedule("yolo3_quick", learning_rate=args.lr, warmup_steps=min(30, args.steps // 5),
                            steps=args.steps, batch_size=args.batch_size)
    _, state, _ = fit_camera(det.config, tune, tune[:args.batch_size], schedule, Path(args.out) / "run", seed=args.seed,
                             eval_every=0, overrides=overrides, init_variables=variables, sizes=MultiScale((args.size,)),
                             eval_size=args.size, progress=not args.no_progress,
                             run_info={"command": command_line(), "experiment": "camera_voc_finetune"})
    return {"params": state["params"], "batch_stats": state["batch_stats"]}


def command_line() -> str:
    return " ".join(["python -m experiments.camera_voc_finetune", *sys.argv[1:]])


def table(rows: list[dict], tune: int, held: int) -> str:
    lines = [f"Shuffle-YOLOv3 trained on the synthetic street benchmark, scored on {held} real VOC2012 images "
             f"held out of the 100 (the other {tune} tune); VOC07 mAP@0.5 at the shared classes, percent.", "",
             "| Row | VOC07 mAP@0.5 | all-point | COCO mAP@[.5:.95] | per class (VOC07 AP) |", "|---|---|---|---|---|"]
    for r in rows:
        s = r["scores"]
        per_class = ", ".join(f"{c} {fmt(v)}" for c, v in s["AP50"].items())
        lines.append(f"| {r['row']} | " + " | ".join(fmt(s[k]) for k in HEADLINE) + f" | {per_class} |")
    return "\n".join(lines) + "\n"


def parse(argv):
    p = argparse.ArgumentParser(prog="python -m experiments.camera_voc_finetune", description=__doc__.split("\n\n")[0])
    p.add_argument("--weights", default=None, help="street-trained weights (default: the zoo's shipped ones)")
    p.add_argument("--voc", default=str(VOC_DIR), help="the 100 VOC2012 images' folder (flat layout)")
    p.add_argument("--tune-images", type=int, default=50)
    p.add_argument("--steps", type=int, default=150)
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--size", type=int, default=EVAL_SIZE, help="letterbox long side (multiple of 32)")
    p.add_argument("--batch-size", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="experiments/records/camera_voc_finetune")
    p.add_argument("--no-progress", action="store_true")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse(argv)
    weights = Path(args.weights) if args.weights else zoo.shipped_weights(MODEL)
    overrides = zoo.trained_fields(weights, CAMERA.weight_fields)
    det = zoo.create(MODEL, **overrides)
    variables = zoo.model_variables(det, weights)
    data = f"voc:{args.voc}"
    mapping = class_map(det.config.classes, source_classes(data))  # model class -> VOC class
    tune, held_out = split_by_id(load_camera_images(data, "all"), args.tune_images)
    tune_model = renamed(tune, {v: k for k, v in mapping.items()})
    adapt = bn_recalibration(det, tune_model, args.batch_size, args.seed, args.size, count_images=len(tune))
    predictor = CameraPredictor(det, None, size=args.size, class_map=mapping)
    rows = [{"row": "zero-shot (street weights)", "scores": held_out_scores(predictor, variables, held_out)},
            {"row": f"BN statistics re-estimated on the {len(tune)} tune images",
             "scores": held_out_scores(predictor, adapt(variables), held_out)}]
    tuned = fine_tune(det, overrides, variables, tune_model, args)
    rows.append({"row": f"fine-tuned {args.steps} steps on the {len(tune)} tune images",
                 "scores": held_out_scores(predictor, tuned, held_out)})
    out = Path(args.out)
    text = table(rows, len(tune), len(held_out))
    atomic.write_json(out / "finetune.json", {
        "command": command_line(), "seed": args.seed, "versions": versions(), "weights": str(weights),
        "class_map": mapping, "tune_ids": [i.image_id for i in tune], "held_out_ids": [i.image_id for i in held_out],
        "steps": args.steps, "lr": args.lr, "size": args.size, "rows": rows})
    atomic.write_text(out / "table.md", text + f"\nCommand: `{command_line()}`\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Train a camera zoo detector (Shuffle-YOLOv3, Darknet53-YOLOv3) on camera images, validating with
the family's protocol (VOC07 mAP@0.5 headline, evaluate_camera): the image modality's `fit` verb
(`dsfec train` reaches it through the Modality record, as it reaches the other families').

Batches come from data.camera.batches.CameraBatchStream (batch s a pure function of (seed, s), its
input size too: resumed runs see the same data at the same sizes), the targets from the family's
pad_batch (models/camera/targets.py, the model's class names); the loop (train.loop) is the shared
one: resumable run directory, JSONL metrics, last-N and best checkpoints, background batch building.
The jitted step is one `jax.jit`, cached per input shape, so multi-scale training compiles each
size once. Before each validation the BN running statistics are re-estimated on PRECISE_BN_IMAGES
unaugmented training images (train/precise_bn.py): with momentum 0.99 they lag far behind the
weights in a run of a few hundred steps, which then scores ~0 whatever it learnt.

Multi-scale per profile (MULTI_SCALE, by schedule name): yolo3_paper trains as darknet does, 320-608
every 10 batches and the last 200 batches at 608; yolo3_quick 320-416 (each size costs a compile of
the train step, the timings: docs/camera.md, "Schedules"; the small sizes are the cheap ones); any
other schedule at 416.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Sequence

from ... import zoo
from ...data.camera.augment import CameraAugment
from ...data.camera.batches import DARKNET_FINAL_SIZE, DARKNET_SIZES, CameraBatchStream, MultiScale
from ...data.camera.images import CameraImage
from ..checks import require_modality
from ..pictures import training_picture
from .evaluate import PROTOCOLS
from ...models.camera.targets import DEFAULT_MAX_BOXES, pad_batch
from .predict import CameraPredictor
from ...train.ema import evaluated
from ...train.loop import RunSpec, run_record, train
from ...train.precise_bn import precise_bn
from ...train.schedules import Schedule

MULTI_SCALE = {"yolo3_paper": MultiScale(DARKNET_SIZES, final_size=DARKNET_FINAL_SIZE),
               "yolo3_quick": MultiScale.span(320, 416)}
FIXED_SIZE = MultiScale((416,))
PRECISE_BN_IMAGES = 64  # training images the BN statistics are re-estimated on before a validation


def multi_scale_for(schedule: Schedule) -> MultiScale:
    return MULTI_SCALE.get(schedule.name, FIXED_SIZE)


def fit_camera(cfg, images: Sequence[CameraImage], val: Sequence[CameraImage], schedule: Schedule,
               run_dir: str | Path, seed: int = 0, steps: int | None = None, augment: bool = True,
               eval_every: int | None = 200, run_info: dict | None = None, progress: bool = True,
               init_variables: dict | None = None, *, overrides: dict | None = None,
               match_classes: Sequence[str] = (), sizes: MultiScale | None = None, eval_size: int = 416,
               max_boxes: int = DEFAULT_MAX_BOXES,
               precise_bn_images: int = PRECISE_BN_IMAGES) -> tuple[zoo.Detector, dict, dict]:
    """Train (or resume) a detector of config `cfg` in run_dir -> (detector, final state, val scores).
    run.json records `cfg.name` and `overrides` (what the caller asked for; default zoo.overrides_of(cfg)).
    Images carry class names among the model's (`class_names` / `num_classes`: the street
    benchmark's 5 classes, see modalities/image/cli.py). `sizes` None: the schedule's multi-scale (MULTI_SCALE);
    validation letterboxes each image to `eval_size` (its long side), after the BN statistics are
    re-estimated on `precise_bn_images` training images (0: not; rounded up to whole batches).
    `match_classes` is the protocol's (camera_voc keeps no match tables)."""
    det = zoo.Detector(cfg)
    family = require_modality(cfg, "image", "fit_camera")
    overrides = zoo.overrides_of(cfg) if overrides is None else overrides
    total = steps or schedule.total_steps(len(images))
    sizes = dataclasses.replace(sizes or multi_scale_for(schedule), total_steps=total)  # the final-size rule's end
    targets = functools.partial(pad_batch, class_names=det.config.classes, max_boxes=max_boxes)
    stream = CameraBatchStream(images, schedule.batch_size, seed, targets, CameraAugment() if augment else None, sizes)
    spec = RunSpec(Path(run_dir), schedule, seed, total_steps=total, progress=progress)
    info = run_record(run_info, cfg.name, overrides, det.config, schedule, seed, total, stream.augment,
                      train_images=len(images), val_images=len(val), multi_scale=sizes.record(),
                      aspect=stream.aspect, eval_size=eval_size, max_boxes=max_boxes,
                      precise_bn_images=precise_bn_images)

    predictor = CameraPredictor(det, None, size=eval_size)  # one jitted network for every validation
    protocol = PROTOCOLS[family.metric.name]

    def validate(state):
        predictor.variables = evaluated(state)
        return protocol.validate(predictor, val, match_classes)[0]

    # BN statistics re-estimated before each validation (train/precise_bn.py: the running ones lag
    # far behind in short runs)
    recalibrate = bn_recalibration(det, images, schedule.batch_size, seed, eval_size, precise_bn_images,
                                   max_boxes, stream.aspect)
    def picture(state) -> bytes:  # TensorBoard's: the predict picture of the first validation image
        from ...data.camera.figure import render_camera_figure

        predictor.variables = evaluated(state)
        return training_picture(predictor, val, lambda item: item.image_id, lambda item, found, keep, title:
                                render_camera_figure(item, found.select(keep), det.config.classes, title))

    state, scores = train(det, stream, spec, info, validate, eval_every or total, init_variables=init_variables,
                          best_key=family.metric.headline, before_eval=recalibrate, picture=picture)
    if scores is None:  # a finished run resumed: nothing trained (re-estimating again gives the same statistics)
        state = recalibrate(state) if recalibrate else state
        scores = validate(state)
    return det, state, scores


def bn_recalibration(det, images: Sequence[CameraImage], batch_size: int, seed: int, eval_size: int,
                     count_images: int = PRECISE_BN_IMAGES, max_boxes: int = DEFAULT_MAX_BOXES,
                     aspect: float | None = None):
    """fn(state) -> state with BN statistics re-estimated on the first `count_images` (rounded up
    to whole batches) of `images`, unaugmented, letterboxed at the evaluation size; None for 0."""
    targets = functools.partial(pad_batch, class_names=det.config.classes, max_boxes=max_boxes)
    calibration = CameraBatchStream(images, batch_size, seed, targets, None, MultiScale((eval_size,)), aspect)
    count = min(-(-count_images // batch_size), calibration.per_epoch)
    return precise_bn(det, lambda: [calibration.batch(k) for k in range(count)]) if count else None

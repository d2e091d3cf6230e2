"""The training benchmark's batches for camera models (modality 'image': Shuffle-YOLOv3,
Darknet53-YOLOv3).

Made as modalities/image/fit.py makes them: images of the family's embedded benchmark (the street
scenes, data seed = the bench's seed) through data.camera.batches.CameraBatchStream, with darknet's
augmentations, letterboxed into one input size (`settings.image_size` on the long side: the 16:9
street frames go into 256 x 416 at 416) and padded box targets of the model's classes
(models/camera/targets.pad_batch). Training draws a new size every 10 batches (multi-scale); the
bench holds one, since each size is its own compiled step and the figures are per size. The model
takes the benchmark's classes, as `dsfec train` gives them (modalities/image/cli.with_data_classes). The point
settings (window, max_pillars, size_pillars, budget_frames) do not apply; only the
`batch * distinct_batches` images that are timed are made.
"""

from __future__ import annotations

import functools

import jax

from ... import zoo
from ...profile.training import model_names


def class_fields() -> dict:
    """num_classes and class_names of the street benchmark (the fields `dsfec train` sets from it)."""
    from ...data.camera.sources import source_classes
    from ...models.camera.family import class_fields as fields_of

    return fields_of(source_classes("street"))


def training_batches(name: str, overrides: dict, settings) -> tuple[zoo.Detector, list[dict], int]:
    """(the network a step trains, `settings.distinct_batches` device batches {'inputs', 'targets'}, 1)."""
    from ...data.camera.augment import CameraAugment
    from ...data.camera.batches import CameraBatchStream, MultiScale
    from ...data.camera.sources import load_camera_images
    from ...models.camera.targets import pad_batch

    det = zoo.create(name, **overrides)
    family = zoo.family_of(det.config)
    images = load_camera_images(family.benchmark, "train", settings.batch * settings.distinct_batches, settings.seed)
    targets = functools.partial(pad_batch, class_names=det.config.classes)
    stream = CameraBatchStream(images, settings.batch, settings.seed, targets, CameraAugment(),
                               MultiScale((settings.image_size,)))
    batches = [stream.batch(k) for k in range(settings.distinct_batches)]  # one epoch: every image once
    return det, [jax.device_put({"inputs": b["inputs"], "targets": b["targets"]}) for b in batches], 1


def note(records: list[dict], settings: dict) -> str:
    """What the train-bench table's footer says of its camera `records` ('' for none)."""
    if not records:
        return ""
    shape = next(iter(records[0]["configs"][0]["input"].values()))
    return (f" Camera models ({model_names(records)}): batch {settings['batch']} street train "
            f"images letterboxed to {shape[1]} x {shape[2]} with darknet's augmentations and padded box targets as "
            "train/fit_camera.py makes them (one input size, no multi-scale), the street benchmark's 5 classes; "
            "windows and pillar slots do not apply; the step is the family's quick schedule's (AdamW).")

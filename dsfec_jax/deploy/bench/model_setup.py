"""What each benchmarked model runs on: the detector, its variables, one synthetic frame (a point
cloud, a range-Doppler map, or a street camera image), and for the point models the Predictor whose
host NMS closes every chain.

Shipped weights are used when the model ships them (trained weights give a realistic score
distribution, so a realistic NMS load); otherwise the detector's own initial variables, labelled
'random' in the records. For YOLO-RD those load the host NMS about as trained weights do: its class
biases start at ultralytics' prior (sigmoid ~1e-4 at stride 8), and 96 of yolov8n's 2016 candidates
pass conf 0.001 at 256 x 64 (a briefly trained yolov8n: a median 60). The camera networks' output
biases start at ultralytics' priors too (models/camera/config.py `prior_bias`), but their initial
batch-norm statistics (mean 0, variance 1) let activations grow through the deep stacks (Darknet53's
boxes overflow to inf at 416); their 'random' variables therefore carry batch statistics measured on
a few street train images (as train/precise_bn.py re-estimates them), a trained network's scale.
"""

from __future__ import annotations

import jax
import numpy as np


def bench_variables(det, name: str) -> tuple[dict, str]:
    """(variables, 'shipped' | 'random') of a registered model."""
    from ... import zoo

    shipped = zoo.shipped_weights(name)
    if shipped.is_file():  # trained weights: realistic score distribution, so a realistic NMS load
        v = zoo.load_variables(det, shipped)
        return {"params": v["params"], "batch_stats": v["batch_stats"]}, "shipped"
    return det.init(jax.random.key(0)), "random"


def model_setup(name: str):
    """A point model: (detector, variables, weights label, frame points, Predictor for the host NMS)."""
    from ... import zoo
    from ...core.defaults import RUN_PILLARS
    from ...data.points.pillarize import select_columns
    from ...data.points.sources import load_frames
    from ...modalities.points.predict import Predictor

    det = zoo.create(name, max_pillars=RUN_PILLARS)
    variables, label = bench_variables(det, name)
    frame = load_frames("synthetic", "test", 1, seed=0)[0]
    points = select_columns(frame, det.config.point_features)
    return det, variables, label, points, Predictor(det, variables, score_threshold=0.1)


def rd_model_setup(name: str):
    """An RD model: (detector, variables, weights label, one synthetic test RD sample)."""
    from ... import zoo
    from ...data.rd.sources import load_rd_samples

    det = zoo.create(name)
    variables, label = bench_variables(det, name)
    return det, variables, label, load_rd_samples("synthetic", "test", 1, seed=0)[0]


CAMERA_BN_IMAGES = 4  # street train images the stand-in variables' batch statistics are measured on


def measured_batch_stats(det, variables: dict, images: np.ndarray) -> dict:
    """`variables` with 'batch_stats' = the batch statistics of one train-mode forward on `images`
    (models/bn_statistics.py, train/precise_bn.py's estimate from one batch)."""
    from ...models.bn_statistics import batch_statistics

    return {"params": variables["params"], "batch_stats": batch_statistics(det)(variables, {"image": images})}


def camera_model_setup(name: str, size: int, overrides: dict | None = None):
    """A camera model: (detector, variables, weights label, one street test image). The classes are
    the shipped weights' run's, else the street benchmark's (what `dsfec train` gives a model trained
    on it); `overrides` (config fields) win."""
    from ... import zoo
    from ...data.camera.batches import eval_input
    from ...data.camera.letterbox import network_shape
    from ...data.camera.sources import load_camera_images, source_classes
    from ...models.camera.family import class_fields

    fields = {**class_fields(source_classes("street")),
              **zoo.trained_fields(zoo.shipped_weights(name), zoo.family_of(name).weight_fields), **(overrides or {})}
    det = zoo.create(name, **fields)
    variables, label = bench_variables(det, name)
    if label == "random":
        train = load_camera_images("street", "train", CAMERA_BN_IMAGES, seed=0)
        hw = network_shape(size, train[0].hw[0] / train[0].hw[1])
        variables = measured_batch_stats(det, variables, np.stack([eval_input(im, hw)[0] for im in train]))
    return det, variables, label, load_camera_images("street", "test", 1, seed=0)[0]

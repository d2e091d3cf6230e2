"""Load a trained detector as a ready predictor: the package's public entry point.

    >>> from dsfec_jax import api
    >>> predictor = api.load("dsfec_s")            # shipped weights (or weights="path.msgpack")
    >>> detections = predictor(points)             # (N, F) radar points or a Frame -> Detections

The predictor is the model's modality's (modalities/registry.modality_of): points -> Detections
(BEV boxes), a range-Doppler sample -> Boxes2D (map cells), a camera image -> Boxes2D (pixels).
"""

from __future__ import annotations

from pathlib import Path

from . import zoo
from .modalities.registry import modality_of


def load(model, /, weights: str | Path | None = None, predictor_options: dict | None = None, **overrides):
    """A ready predictor: `api.load("dsfec_s")(points) -> Detections`, `api.load("yolov8n")(rd_sample)
    -> Boxes2D`, `api.load("shuffle_yolov3")(image) -> Boxes2D` (shipped weights by default).

    `model` is a zoo name, with `overrides` of its config fields; the fields the training data set
    (the camera family's classes) come from the weights' run unless given. Or a resolved config,
    used as it is (no overrides)."""
    if isinstance(model, str):
        path = Path(weights) if weights else zoo.shipped_weights(model)
        cfg = zoo.config(model, **{**zoo.trained_fields(path, zoo.family_of(model).weight_fields), **overrides})
    elif overrides:
        raise TypeError(f"api.load of a config takes no overrides (got {sorted(overrides)}): resolve them in the config")
    else:
        cfg = model
    detector, variables = zoo.trained_detector(cfg, weights)
    # a loaded predictor keeps its weights: compiled into the program (modalities/inference.py)
    options = {"constant_weights": True, **(predictor_options or {})}
    return modality_of(cfg).predictor(detector, variables, **options)


def tune_host() -> dict:
    """The `dsfec` commands' host-memory settings for your own script (core/host_memory): XLA's
    temporary buffers kept on the heap between calls (glibc's mallopt) and calls run inline. Call it
    first, before anything runs JAX; it changes glibc's allocator for the whole process (the peak heap
    is kept until exit). -> {'keep_buffers': bool, 'inline_dispatch': bool}, what applied."""
    from .core.host_memory import tune_in_process

    return tune_in_process()


def read_files(model, *paths: str | Path, columns: str | None = None):
    """A user's own files as the model's inputs, ready for `predictor.predict_samples(items)` (ids: the
    paths): camera images, radar point clouds (.pcd, .bin with `columns` = vod | tj4d | names), RD
    maps or raw TI ADC captures (.npy). `paths`: files, folders or globs (modalities/files.py);
    InputFileError names a bad file. `model`: a zoo name or a config, as for `load`."""
    from .modalities.files import read_files as read

    cfg = zoo.config(model) if isinstance(model, str) else model
    return read(modality_of(cfg).files, [str(p) for p in paths], cfg, columns)

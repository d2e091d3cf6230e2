"""The depth network's zoo record (models/auxiliary.py): `zoo.config("monodepth_street")`,
`zoo.create_auxiliary(...)`, `zoo.shipped_weights(...)` and `zoo.load_variables` work for it as
for a detector. Its predictor and training are the image modality's (modalities/image/depth.py,
fit_depth.py)."""

from __future__ import annotations

import numpy as np

from ..auxiliary import Auxiliary
from .config import TINY, MonodepthConfig
from .net import MonodepthNet, init_variables


def dummy_inputs(cfg: MonodepthConfig, batch_size: int = 1) -> tuple:
    """(images,): (batch_size, height, width, 3) float32 in [0, 1], the network's one input."""
    return (np.random.default_rng(0).random((batch_size, cfg.height, cfg.width, 3), np.float32),)


FIRST_FORMAT = "dsfec_jax.monodepth"  # the manifest's "format" before the network joined the zoo
FIRST_FORMAT_TRAINING = ("seed", "train_frames", "init_chain", "versions")  # kept under the same names


def first_format_training(manifest: dict) -> dict | None:
    """The training record of a weights manifest in the depth network's first format (None for any
    other): it held the whole "config" and the run's provenance ("train_command", "seed",
    "train_frames", "init_chain", "versions") at its top level, where the zoo's layout keeps them
    under "training" as a detector's shipped weights do (command, seed, config, versions)."""
    if manifest.get("format") != FIRST_FORMAT:
        return None
    config = manifest.get("config")
    return {"model": config.get("name") if isinstance(config, dict) else None, "command": manifest.get("train_command"),
            "config": config, **{k: manifest[k] for k in FIRST_FORMAT_TRAINING if k in manifest}}


# monodepth_street: the shipped weights' network (zoo.shipped_weights: dsfec_jax/weights/depth/monodepth_street.msgpack);
# monodepth_tiny: tests and smoke runs
VARIANTS = {cfg.name: cfg for cfg in (MonodepthConfig(), TINY)}

AUXILIARY = Auxiliary(
    name="depth", task="disparity (a fraction of the image width) of one camera image", config_class=MonodepthConfig,
    variants=VARIANTS, build=MonodepthNet, init=init_variables, dummy_inputs=dummy_inputs,
    config_from_dict=MonodepthConfig.from_dict, first_format_training=first_format_training)

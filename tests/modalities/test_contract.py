"""The Modality contract, over every registered family: two items of the family's embedded
benchmark (the modality's load_samples) -> the modality's predictor (random weights at tiny
shapes) -> the protocol the family names (registry.protocol) -> the headline metric, a finite
number. Shared code (the CLI, search trials, shipping) goes exactly this way, so a family whose
record points at another modality's samples, predictor or protocol fails here."""

from __future__ import annotations

import dataclasses
import math

import pytest
from conftest import TINY_GRID, random_variables

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.modalities.registry import MODALITIES, modality_of, protocol

# family -> (a variant, config overrides, predictor options) that compile in a second or two
TINY = {
    "dsfec": ("dsfec_s", {"grid": TINY_GRID, "max_pillars": 96, "max_points": 4}, {}),
    "radarnext": ("radarnext_fpn", {"grid": Grid((0.0, 10.24), (-5.12, 5.12), (-3.0, 2.0), 0.16),
                                    "layer_nums": (1, 1, 1), "max_points": 4, "max_pillars": 96}, {}),
    "yolo_rd": ("yolov8n", {}, {"representation": RDRepresentation(fit="resize", input_hw=(64, 32))}),
    "camera": ("shuffle_yolov3", {"widths": (16, 16, 32, 32, 64), "repeats": (1, 1, 1, 1, 1),
                                  "head_widths": (16, 32, 64), "head_units": 1}, {"size": 64}),
}


def test_every_family_has_a_tiny_setup_here():
    assert set(TINY) == set(zoo.FAMILIES)


@pytest.mark.parametrize("family_name", sorted(zoo.FAMILIES))
def test_benchmark_items_go_through_predictor_and_protocol_to_the_headline(family_name):
    family = zoo.FAMILIES[family_name]
    variant, overrides, options = TINY[family_name]
    cfg = zoo.config(variant, **overrides)
    modality = modality_of(cfg)
    assert modality is MODALITIES[family.modality] and family.metric.name in modality.protocols
    samples = modality.load_samples(family, family.benchmark, "val", 2, 0)
    detector = zoo.Detector(cfg)
    predictor = modality.predictor(detector, random_variables(detector, 0), **options)
    scores, tables = protocol(family.metric.name).validate(predictor, samples)
    headline = scores[family.metric.headline]
    assert isinstance(headline, (int, float)) and math.isfinite(headline) and 0 <= headline <= 100
    assert tables == {}  # no match tables unless asked for


def test_a_protocol_fed_another_modality_s_samples_fails():
    """The contract can fail: the camera protocol with point frames is an error, not a score."""
    family = zoo.FAMILIES["dsfec"]
    frames = MODALITIES["points"].load_samples(family, family.benchmark, "val", 2, 0)
    variant, overrides, options = TINY["camera"]
    detector = zoo.create(variant, **overrides)
    predictor = MODALITIES["image"].predictor(detector, random_variables(detector, 0), **options)
    with pytest.raises((AttributeError, TypeError, ValueError)):
        protocol("camera_voc").validate(predictor, frames)



def test_a_search_trial_trains_on_its_modality_s_samples(monkeypatch, tmp_path):
    """A trial of a camera model (the family has no recipe yet: one is stubbed in) loads street
    images and calls the image modality's fit; it used to fall through to point frames."""
    from search import recipes, trial

    from dsfec_jax.data.camera.images import CameraImage
    from dsfec_jax.train.schedules import get_schedule

    seen = {}

    def fit(cfg, samples, val, schedule, run_dir, seed, **options):
        seen.update(model=cfg.name, samples=list(samples), val=list(val), options=options)
        return None, None, {"mAP50": 1.0}

    monkeypatch.setitem(MODALITIES, "image", dataclasses.replace(MODALITIES["image"], fit=fit))
    recipe = recipes.Recipe("tiny", get_schedule("yolo3_quick"), train_frames=2, val_frames=1, grid=None,
                            max_pillars=None, window=None, latency_repeats=1, supernet_steps=None, light_profile=True)
    monkeypatch.setitem(recipes.RECIPES, "camera", {"tiny": recipe})
    spec = {"base": "shuffle_yolov3", "label": "base", "overrides": {}, "recipe": "tiny", "data": "street", "seed": 0}
    assert trial._fit_trial(spec, tmp_path) == {"mAP50": 1.0}
    assert seen["model"] == "shuffle_yolov3" and len(seen["samples"]) == 2 and len(seen["val"]) == 1
    assert all(isinstance(s, CameraImage) for s in seen["samples"] + seen["val"])
    assert "window" not in seen["options"]  # the point families' option only

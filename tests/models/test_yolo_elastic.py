"""Elastic widths of the YOLOv8 bases (the NAS space's subnets are ordinary configs)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from dsfec_jax import zoo


def _shapes(model, **overrides):
    det = zoo.create(model, **overrides)
    return det, jax.eval_shape(lambda: det.init(jax.random.key(0)))["params"]


def test_ratios_of_one_are_the_yaml_model():
    _, plain = _shapes("yolov8n_adapter")
    _, ones = _shapes("yolov8n_adapter", backbone_width_ratios=(1, 1, 1, 1, 1), neck_width_ratios=(1, 1, 1))
    assert jax.tree.map(lambda a: a.shape, plain) == jax.tree.map(lambda a: a.shape, ones)


def test_ratios_set_the_widths_of_their_blocks_and_levels():
    det, p = _shapes("yolov8n", backbone_width_ratios=(0.5, 1, 0.25, 1, 1), neck_width_ratios=(1, 0.5, 0.25))
    bb, neck, head = p["backbone"], p["neck"], p["head"]
    assert bb["layer0"]["conv"]["kernel"].shape[-1] == 8  # block 1: 16 x 1/2
    assert bb["layer3"]["conv"]["kernel"].shape[-1] == 16  # block 3 (layers 3-4): 64 x 1/4
    assert bb["layer4"]["cv2"]["conv"]["kernel"].shape[-1] == 16
    assert bb["layer5"]["conv"]["kernel"].shape[-1] == 128  # block 4 untouched
    assert neck["layer15"]["cv2"]["conv"]["kernel"].shape[-1] == 64  # level 1 (P3) at 1
    assert neck["layer12"]["cv2"]["conv"]["kernel"].shape[-1] == 64  # level 2: 128 x 1/2
    assert neck["layer21"]["cv2"]["conv"]["kernel"].shape[-1] == 64  # level 3: 256 x 1/4
    assert head["box0_0"]["conv"]["kernel"].shape[-1] == 64 and head["box2_0"]["conv"]["kernel"].shape[-1] == 16
    assert head["cls1_0"]["conv"]["kernel"].shape[-1] == 32  # c3 = 64 (the full model's P3 width) x 1/2
    outs = jax.eval_shape(lambda: det.apply(det.init(jax.random.key(0)), det.dummy_inputs(1)))  # shapes, no compile
    assert [o.shape for o in outs] == [(1, 32, 8, 70), (1, 16, 4, 70), (1, 8, 2, 70)]


@pytest.mark.parametrize("field,value,match", [
    ("backbone_width_ratios", (1, 1, 1, 1), "5 ratios"),
    ("neck_width_ratios", (1, 0, 1), r"3 ratios in \(0, 1\]"),
])
def test_bad_ratios_name_the_field(field, value, match):
    with pytest.raises(ValueError, match=f"{field}.*{match}"):
        zoo.config("yolov8n", **{field: value})


def test_elastic_widths_are_v8_only():
    with pytest.raises(ValueError, match="neck_width_ratios.*arch is 'v8'"):
        zoo.config("yolov10n", neck_width_ratios=(0.5, 1, 1))
    assert np.isclose(zoo.config("yolov9t").backbone_width_ratios, 1).all()

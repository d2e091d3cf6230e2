"""experiments.camera_voc_finetune on the 100 real VOC images at a tiny input: the split, the renaming
into the model's classes, the three rows and the record; a fine-tune that moves the weights."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.core import checkpoint
from dsfec_jax.data.camera.images import CameraImage
from experiments import camera_voc_finetune as exp
from conftest import shared_data_dir

STREET = {"num_classes": 5, "class_names": ("car", "truck", "bus", "pedestrian", "cyclist")}


def test_split_is_by_sorted_id_and_renaming_drops_other_classes():
    def image(name, labels):
        boxes = Boxes2D(np.tile([[0.0, 0.0, 4.0, 4.0]], (len(labels), 1)), np.array(labels, dtype="<U32"))
        return CameraImage(name, np.zeros((8, 8, 3), np.uint8), boxes)

    tune, held = exp.split_by_id([image("b", []), image("a", ["person", "dog", "car"]), image("c", [])], 2)
    assert [i.image_id for i in tune] == ["a", "b"] and [i.image_id for i in held] == ["c"]
    out = exp.renamed(tune, {"person": "pedestrian", "car": "car"})
    assert list(out[0].boxes.names) == ["pedestrian", "car"] and len(out[1].boxes) == 0
    with pytest.raises(ValueError, match="--tune-images 3: expected 1..2"):
        exp.split_by_id([image("a", []), image("b", []), image("c", [])], 3)


def test_three_rows_on_the_held_out_real_images(tmp_path):
    det = zoo.create("shuffle_yolov3", **STREET)
    variables = det.init(jax.random.key(0))
    weights = tmp_path / "street.msgpack"
    checkpoint.save(weights, {"params": variables["params"], "batch_stats": variables["batch_stats"]},
                    {"training": {"overrides": {k: list(v) if isinstance(v, tuple) else v for k, v in STREET.items()}}})
    voc = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    out = tmp_path / "out"
    assert exp.main(["--weights", str(weights), "--voc", str(voc), "--tune-images", "90", "--steps", "2",
                     "--size", "64", "--batch-size", "4", "--out", str(out), "--no-progress"]) == 0
    record = json.loads((out / "finetune.json").read_text())
    assert len(record["tune_ids"]) == 90 and len(record["held_out_ids"]) == 10
    assert record["tune_ids"] == sorted(record["tune_ids"]) and record["tune_ids"][-1] < record["held_out_ids"][0]
    assert record["class_map"] == {"car": "car", "bus": "bus", "pedestrian": "person", "cyclist": "bicycle"}
    rows = record["rows"]
    assert [r["row"].split()[0] for r in rows] == ["zero-shot", "BN", "fine-tuned"]
    assert all(set(r["scores"]["classes"]) == {"car", "bus", "person", "bicycle"} for r in rows)
    assert all(r["scores"]["images"] == 10 for r in rows)
    # different BN statistics and weights change the detections, so the rows cannot all be equal
    assert len({json.dumps(r["scores"]["num_det"], sort_keys=True) for r in rows}) > 1
    assert "python -m experiments.camera_voc_finetune" in (out / "table.md").read_text()
    assert (out / "run" / "checkpoints").is_dir()

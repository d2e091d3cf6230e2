"""`dsfec train | eval | predict | ship` for the camera family: one round trip of a tiny
Shuffle-YOLOv3 on two street frames at 64 px (the compiles dominate: one train step size, one
inference program shared by validation, eval and ship through the tests' compilation cache), the
classes a street-trained model takes from its run when scored on real VOC images, the files predict
writes, and what the commands refuse, by name (export, quantize and bench: tests/modalities/image/test_image_deploy.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from builders import tensorboard_events
from conftest import shared_data_dir
from PIL import Image

from dsfec_jax import cli, zoo
from dsfec_jax.models.camera.family import CAMERA_VOC_PROTOCOL

STREET = ["car", "truck", "bus", "pedestrian", "cyclist"]
TINY = ["--set", "widths=(16, 16, 32, 32, 64)", "--set", "repeats=(1, 1, 1, 1, 1)", "--set", "head_widths=(16, 32, 64)",
        "--set", "head_units=1"]
KEYS = set(CAMERA_VOC_PROTOCOL.keep) | {"coco_AP", "num_gt", "images", "classes", "gt_left_out"}


def last_json(capsys):
    return json.loads(capsys.readouterr().out)  # the command's one JSON document


def test_train_eval_predict_ship_round_trip(tmp_path, capsys, uncompiled_init):
    run = tmp_path / "run"
    assert cli.main(["train", "--model", "shuffle_yolov3", "--data", "street", "--steps", "2", "--batch-size", "2",
                     "--frames", "2", "--val-frames", "2", "--eval-every", "0", "--sizes", "64", "--size", "64",
                     "--run-dir", str(run), *TINY]) == 0
    final = last_json(capsys)["final"]
    assert KEYS <= set(final) and final["images"] == 2 and final["classes"] == STREET
    info = json.loads((run / "run.json").read_text())
    assert info["schedule"]["name"] == "yolo3_quick" and info["multi_scale"] == {"sizes": [64], "every": 10}
    assert info["overrides"]["class_names"] == STREET and info["overrides"]["num_classes"] == 5  # from the data
    best = run / "checkpoints" / "best"  # its one step directory: what --weights reads
    assert info["schedule"]["ema"] is True  # the family's weight EMA: eval --weights below reads the average
    assert [e.step for e in tensorboard_events(run).Images("val/predictions")] == [2]

    assert cli.main(["eval", "--model", "shuffle_yolov3", "--weights", str(best), "--data", "street", "--split",
                     "val", "--frames", "2", "--size", "64", "--json", *TINY]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert "running the first batch (a JAX predictor compiles its network on it)" in captured.err
    assert "detecting in 2 images: 100%" in captured.err  # the bar is on stderr, the JSON alone on stdout
    assert KEYS <= set(result) and result["protocol"] == "camera_voc" and result["score_threshold"] == 0.005
    assert result["mAP50"] == final["mAP50"] and result["classes_scored"] == STREET  # validation's images

    root = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    pred, gt, png = tmp_path / "dets.json", tmp_path / "gt.json", tmp_path / "png"
    assert cli.main(["predict", "--model", "shuffle_yolov3", "--weights", str(best), "--data", f"voc:{root}",
                     "--split", "all", "--frames", "2", "--size", "64", "--out", str(pred), "--gt-out", str(gt),
                     "--png-dir", str(png), "--json", *TINY]) == 0
    voc = last_json(capsys)
    # the street classes (from the run) renamed into VOC's; truck has no VOC class, other VOC classes are left out
    assert voc["classes_scored"] == ["car", "bus", "person", "bicycle"] and voc["gt_left_out"] == {"aeroplane": 2}
    assert voc["num_gt"] == {"car": 0, "bus": 0, "person": 3, "bicycle": 0}
    rows = json.loads(pred.read_text())
    assert rows and min(r["score"] for r in rows) >= 0.005
    names = {c["id"]: c["name"] for c in json.loads(gt.read_text())["categories"]}
    assert [names[k] for k in sorted(names)] == voc["classes_scored"]
    width, height = Image.open(png / "2007_000027.png").size
    assert (width, height) == (700, 707)  # a figure of the 486 x 500 image, scaled to a 6-inch width

    shipped = tmp_path / "weights"
    assert cli.main(["ship", "--model", "shuffle_yolov3", "--run-dir", str(run), "--frames", "2",
                     "--out-dir", str(shipped)]) == 0
    capsys.readouterr()
    measured = json.loads((shipped / "shuffle_yolov3.msgpack.json").read_text())["measured"]
    assert measured["val"]["mAP50"] == final["mAP50"] and measured["test"]["protocol"] == "camera_voc"
    assert measured["test"]["data"] == "street"
    assert cli.main(["eval", "--model", "shuffle_yolov3", "--weights", str(shipped / "shuffle_yolov3.msgpack"),
                     "--frames", "2", "--size", "64", "--json", *TINY]) == 0  # classes from the shipped manifest
    assert last_json(capsys)["mAP50"] == measured["test"]["mAP50"]

    # the average's gain: both weight sets get the run's precise BN, and the average scores as shipped
    from experiments import ema_gain

    assert ema_gain.main(["--run-dir", str(run), "--frames", "2", "--record", str(tmp_path / "ema.json")]) == 0
    gain = json.loads((tmp_path / "ema.json").read_text())
    assert gain["checkpoint"]["ema_updates"] == 2
    figures = [(split, key) for split in ("val", "test") for key in ("mAP50", "coco_mAP50_95")]
    assert [gain["measured"]["ema"][s][k] for s, k in figures] == [measured[s][k] for s, k in figures]


@pytest.mark.parametrize("argv,message", [
    (["export", "--model", "yolov3_darknet53", "--out", "x"], "pass --weights"),  # Darknet53 ships no weights
    (["train", "--model", "shuffle_yolov3", "--window", "64", "--run-dir", "x"], "--window applies to point-cloud"),
    (["train", "--model", "dsfec_s", "--sizes", "320,416", "--run-dir", "x"], "--sizes and --size apply to camera"),
    (["eval", "--model", "yolov8n", "--size", "416"], "--size applies to camera models"),
    (["eval", "--model", "shuffle_yolov3", "--data", "voc:/nonexistent"], "voc:DIR with an existing folder"),
    (["eval", "--model", "shuffle_yolov3", "--runtime", "onnx"], "--runtime onnx needs --onnx DIR"),
    (["train", "--model", "shuffle_yolov3", "--sizes", "300,416", "--run-dir", "x"], "multiples of 32"),
    (["eval", "--model", "shuffle_yolov3", "--size", "400"], "--size 400: expected a multiple of 32"),
])
def test_what_the_camera_commands_refuse(argv, message):
    with pytest.raises(SystemExit) as err:
        cli.main(argv)
    assert message in str(err.value)


def test_predict_on_a_truncated_jpeg_exits_with_a_message_naming_it(tmp_path):
    """Images are decoded as the loop reaches them: a cut-off JPEG is a message, not a traceback
    (the first image of the loop, so nothing is compiled before it)."""
    database = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    root = tmp_path / "voc"
    (root / "gts" / "pascalvoc_format").mkdir(parents=True)
    (root / "images").mkdir()
    xml = "2007_000027.xml"
    (root / "gts" / "pascalvoc_format" / xml).write_bytes((database / "gts" / "pascalvoc_format" / xml).read_bytes())
    whole = (database / "images" / "2007_000027.jpg").read_bytes()
    (root / "images" / "2007_000027.jpg").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(SystemExit) as err:
        cli.main(["predict", "--model", "shuffle_yolov3", "--data", f"voc:{root}", "--split", "all", "--size", "64",
                  "--out", str(tmp_path / "dets.json")])
    message = str(err.value)
    assert message.startswith("dsfec predict: ") and "2007_000027.jpg: not a readable image" in message
    assert "truncated" in message and not (tmp_path / "dets.json").exists()

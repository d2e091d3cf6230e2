"""Camera export (Shuffle-YOLOv3, Darknet53-YOLOv3): ONNX Runtime's decoded boxes and scores against
the jitted JAX network and decode, OrtCameraPredictor's detections against CameraPredictor's on
street frames (the same letterbox and host NMS around either network), INT8 that runs close to the
float graph with the decode left in float, the bench's camera chains and the training benchmark's
camera batches. Tiny networks (the layers of the zoo's, narrower) at a 64 x 96 input with stand-in
weights: random weights whose batch-norm statistics are measured on 4 street train images (as the
bench's stand-in variables are), so the outputs follow the image (scores differ between two frames
by 0.04-0.07 at the median anchor) and spread over 0.002-0.98: NMS has hundreds of distinct
candidates to keep or drop. (Random statistics instead leave the scores within 1e-4 of each other
from frame to frame, and INT8 calibrated on black images as close to float as on street images.)"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from conftest import random_variables
from dsfec_jax import cli, zoo
from dsfec_jax.data.camera.batches import eval_input
from dsfec_jax.data.camera.sources import load_camera_images
from dsfec_jax.modalities.image.ort import OrtCameraPredictor
from dsfec_jax.modalities.image.export import export_camera
from dsfec_jax.modalities.image.quantize import quantize_camera
from dsfec_jax.deploy.bench import timing
from dsfec_jax.modalities.image.bench import measured_batch_stats
from dsfec_jax.modalities.image.ort import graph_input_hw
from dsfec_jax.modalities.image.predict import CameraPredictor, decoding_network

STREET = ("car", "truck", "bus", "pedestrian", "cyclist")
TINY = {"widths": (16, 16, 32, 32, 64), "repeats": (1, 1, 1, 1, 1), "head_widths": (16, 32, 64), "head_units": 1,
        "num_classes": 5, "class_names": STREET}
SIZE = 96
HW = (64, 96)  # the 16:9 street frames (416 x 234) letterboxed at long side 96
ANCHORS = 3 * (8 * 12 + 4 * 6 + 2 * 3)  # 378 candidate boxes at 64 x 96


@pytest.fixture(scope="module")
def frames():
    return load_camera_images("street", "val", 2, seed=3)


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """name -> (detector, variables, export dir); only shuffle_yolov3 also writes model.jax_export."""
    out, calibration = {}, letterboxed(load_camera_images("street", "train", 4, seed=0))
    for seed, name in enumerate(("shuffle_yolov3", "yolov3_darknet53")):
        det = zoo.create(name, **TINY)
        variables = measured_batch_stats(det, random_variables(det, seed), calibration)
        path = tmp_path_factory.mktemp(name)
        export_camera(det, variables, path, source={"command": "test"}, input_hw=HW,
                      jax_export=name == "shuffle_yolov3")
        out[name] = det, variables, path
    return out


def letterboxed(frames) -> np.ndarray:
    return np.stack([eval_input(f, HW)[0] for f in frames])


def assert_same_detections(got, want, score_tol=1e-5, box_rtol=1e-5):
    """The same detections up to the order of near-tied scores (random weights leave candidates of
    one class within float32 noise of each other, which either runtime may rank first): every
    detection finds one of the same class, score and box on the other side; box corners agree to
    1e-4 px + `box_rtol` of the box's long side (exp(tw) scales float32 noise with the box: measured
    5e-6 of a 375 px box)."""
    assert len(got) == len(want)
    np.testing.assert_array_equal(np.sort(got.names), np.sort(want.names))
    np.testing.assert_allclose(got.scores, want.scores, atol=score_tol)  # both sorted by score
    side = (want.xyxy[:, 2:] - want.xyxy[:, :2]).max(1)
    close = ((got.names[:, None] == want.names[None])
             & (np.abs(got.scores[:, None] - want.scores[None]) <= score_tol)
             & (np.abs(got.xyxy[:, None] - want.xyxy[None]).max(-1) <= 1e-4 + box_rtol * side[None]))
    assert close.any(1).all() and close.any(0).all(), np.flatnonzero(~close.any(1))


@pytest.mark.parametrize("name", ["shuffle_yolov3", "yolov3_darknet53"])
def test_onnx_boxes_and_scores_match_the_jitted_decode(name, exports, frames):
    """Every anchor's box to 2e-5 of the largest box coordinate and every class score to 2e-5 (measured
    up to 5.6e-6 and 4.1e-6; BN means shifted by 1e-3 in the export give 2e-2)."""
    det, variables, path = exports[name]
    images = letterboxed(frames)
    got_boxes, got_scores = OrtCameraPredictor(path).decoded(images)
    want_boxes, want_scores = (np.asarray(a) for a in jax.jit(decoding_network(det))(variables, images))
    assert got_boxes.shape == want_boxes.shape == (2, ANCHORS, 4) and got_scores.shape == (2, ANCHORS, 5)
    assert np.isfinite(want_boxes).all() and 0 < want_scores.min() < want_scores.max() < 1  # not saturated
    assert np.median(np.abs(want_scores[0] - want_scores[1])) > 0.01  # the network reads the image
    box_error = np.abs(got_boxes - want_boxes).max() / np.abs(want_boxes).max()
    score_error = np.abs(got_scores - want_scores).max()
    print(f"{name}: box error {box_error:.2e} of the largest coordinate, score error {score_error:.2e}")
    assert box_error <= 2e-5 and score_error <= 2e-5


def test_ort_predictor_detections_equal_the_camera_predictor(exports, frames):
    """The same letterbox, NMS and mapping back on both sides: the same boxes, in image pixels."""
    det, variables, path = exports["shuffle_yolov3"]
    ours = OrtCameraPredictor(path).predict_samples(frames)
    ref = CameraPredictor(det, variables, size=SIZE).predict_samples(frames)
    assert ours.keys() == ref.keys() == {f.image_id for f in frames}
    for image_id, want in ref.items():
        got = ours[image_id]
        assert len(want) == 300  # random weights: ~all candidates pass 0.005, NMS keeps more than 300
        assert_same_detections(got, want)
        assert got.xyxy[:, 2].max() <= 416 and got.xyxy[:, 3].max() <= 234  # the frame's pixels, not the input's


def test_manifest_and_jax_export_artifact(exports):
    det, _, path = exports["shuffle_yolov3"]
    manifest = json.loads((path / "deploy.json").read_text())
    assert manifest["model"] == "shuffle_yolov3" and manifest["modality"] == "image"
    assert manifest["inputs"] == ["image"] and manifest["outputs"] == ["boxes", "scores"]
    assert manifest["input_hw"] == list(HW) and manifest["input_shapes"] == {"image": [1, *HW, 3]}
    assert manifest["classes"] == list(STREET)
    assert manifest["letterbox"]["size"] == SIZE and manifest["letterbox"]["rect"]
    assert manifest["postprocess"] == {"where": "host", "multi_label": True, "score_threshold": 0.005,
                                       "iou_threshold": 0.45, "max_detections": 300, "pre_top_k": 30000}
    assert manifest["config"]["depthwise_impl"] == "grouped" and manifest["config"]["kernels"] == "plain"
    assert manifest["source"] == {"command": "test"} and manifest["versions"]["onnxruntime"]
    exported = jax.export.deserialize(bytearray((path / "model.jax_export").read_bytes()))
    assert [a.shape for a in exported.in_avals] == [(1, *HW, 3)]
    assert [a.shape for a in exported.out_avals] == [(1, ANCHORS, 4), (1, ANCHORS, 5)]


def test_int8_is_close_to_float_with_the_decode_in_float(exports, frames, tmp_path):
    """The median anchor's scores within 0.03 of the float graph's (a loose bound for a random
    network: measured 0.017 with min/max calibration on 4 street images, 0.037 on 4 black images),
    and the exp / sigmoid decode after the last DequantizeLinear."""
    import onnx

    _, _, path = exports["shuffle_yolov3"]
    out = quantize_camera(path, tmp_path, load_camera_images("street", "train", 4, seed=0))
    model = onnx.load(str(out["onnx"]))
    ops = [n.op_type for n in model.graph.node]
    assert ops.count("QuantizeLinear") >= 20 and "Conv" in ops
    consumers = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    below, frontier = set(), [n for n in model.graph.node if n.op_type == "Exp"]  # the box decode's
    assert frontier
    while frontier:
        n = frontier.pop()
        below.add(n.op_type)
        frontier += [c for o in n.output for c in consumers.get(o, [])]
    assert "QuantizeLinear" not in below and "DequantizeLinear" not in below, below
    manifest = json.loads(out["manifest"].read_text())
    assert manifest["quantization"]["calibration_frames"] == 4 and manifest["letterbox"]["size"] == SIZE
    assert out["int8_bytes"] < out["fp32_bytes"]
    images = letterboxed(frames)
    fp32 = OrtCameraPredictor(path).decoded(images)
    int8 = OrtCameraPredictor(tmp_path).decoded(images)
    score_error = np.median(np.abs(int8[1] - fp32[1]))
    print(f"INT8 against FP32: median score difference {score_error:.4f} "
          f"(max {np.abs(int8[1] - fp32[1]).max():.3f}), median box difference "
          f"{np.median(np.abs(int8[0] - fp32[0])):.2f} px")
    assert 0 < score_error < 0.03
    detections = OrtCameraPredictor(tmp_path).predict_samples(frames)
    assert all(len(d) > 0 and np.isfinite(d.xyxy).all() for d in detections.values())


def test_the_bench_chains_run_and_agree(tmp_path, monkeypatch):
    """jax, onnx and onnx-int8 chains of one street image: each its predictor's own stages, the same
    detections from JAX and ONNX Runtime as from CameraPredictor; the stand-in variables carry
    measured batch statistics."""
    from dsfec_jax.deploy.bench import stages
    from dsfec_jax.modalities.image import bench as stages_camera

    # the initial weights without compiling init (~10 s); their batch statistics are still measured
    monkeypatch.setattr(stages_camera, "bench_variables", lambda det, name: (random_variables(det, 5), "random"))
    monkeypatch.setattr(stages_camera, "CALIBRATION_IMAGES", 2)
    monkeypatch.setattr(stages, "JAX_BATCHES", (1,))
    chains = stages_camera.camera_chains("shuffle_yolov3", ["jax", "onnx", "onnx-int8"], 1, tmp_path, repeats=1,
                                   size=SIZE, overrides=TINY)
    assert set(chains) == {"jax", "onnx", "onnx-int8"}
    outputs = {}
    for rt, (steps, fields) in chains.items():
        assert [s for s, _ in steps] == list(stages_camera.STAGES) == ["letterbox", "network_decode", "nms", "to_image"]
        assert fields["weights"] == "random" and fields["input_hw"] == list(HW)
        x = None
        for _, fn in steps:
            x = fn(x)
        outputs[rt], = x  # one image's Boxes2D
    assert set(chains["jax"][1]["throughput_fps"]) == {"1"}
    assert len(outputs["jax"]) > 0
    assert_same_detections(outputs["onnx"], outputs["jax"])
    samples = timing.time_chains({rt: steps for rt, (steps, _) in chains.items()}, repeats=2, warmup=0)
    assert all(len(s["total"]) == 2 and min(s["total"]) > 0 for s in samples.values())


def test_camera_train_batches_are_made_as_training_makes_them():
    from dsfec_jax.modalities.registry import modality_of
    from dsfec_jax.profile import training

    settings = training.Settings(batch=2, repeats=1, warmup=0, distinct_batches=2, image_size=96)
    assert training.model_overrides("yolov3_darknet53", settings, modality_of("yolov3_darknet53")) == {"num_classes": 5, "class_names": STREET}
    training.check_models(["shuffle_yolov3", "yolov8n", "dsfec_s"], settings, None, modality_of)
    det, batches, windows = modality_of("shuffle_yolov3").train_bench_batches("shuffle_yolov3", {**TINY}, settings)
    assert det.config.classes == STREET and windows == 1 and len(batches) == 2
    b = batches[0]
    assert {k: v.shape for k, v in b["inputs"].items()} == {"image": (2, *HW, 3)}
    assert set(b["targets"]) == {"gt_boxes", "gt_labels", "gt_mask"} and b["targets"]["gt_mask"].any()
    assert not np.array_equal(b["inputs"]["image"], batches[1]["inputs"]["image"])  # distinct images
    with pytest.raises(ValueError, match="image_size=100"):
        training.Settings(image_size=100)


def test_the_export_refuses_images_of_another_shape_naming_the_fix(exports):
    _, _, path = exports["shuffle_yolov3"]
    manifest = json.loads((path / "deploy.json").read_text())
    assert graph_input_hw(manifest, (234, 416), "m") == HW
    with pytest.raises(ValueError, match=r"600 x 300 letterboxes into \(96, 64\).*--input-hw 96,64"):
        graph_input_hw(manifest, (600, 300), "m")  # a portrait image
    square = {**manifest, "input_hw": [96, 96], "letterbox": {**manifest["letterbox"], "rect": False}}
    assert graph_input_hw(square, (500, 375), "m") == (96, 96)  # a square takes every image


def test_cli_export_quantize_and_eval_onnx(exports, tmp_path, capsys):
    """The commands around a checkpoint: export at --size, quantize, eval --runtime onnx (the FP32
    export scores what the JAX predictor scores), and what they refuse."""
    from dsfec_jax.core import checkpoint

    det, variables, _ = exports["shuffle_yolov3"]
    weights = tmp_path / "w.msgpack"
    checkpoint.save(weights, variables, {"training": {"overrides": {"num_classes": 5, "class_names": list(STREET)}}})
    tiny = [a for k, v in TINY.items() if k not in ("num_classes", "class_names") for a in ("--set", f"{k}={v}")]
    fp32, int8 = tmp_path / "fp32", tmp_path / "int8"
    assert cli.main(["export", "--model", "shuffle_yolov3", "--weights", str(weights), "--out", str(fp32),
                     "--size", str(SIZE), *tiny]) == 0
    assert json.loads((fp32 / "deploy.json").read_text())["input_hw"] == list(HW)
    assert cli.main(["quantize", "--onnx", str(fp32), "--out", str(int8), "--calib-frames", "2"]) == 0
    capsys.readouterr()
    scores = {}
    for runtime, extra in (("jax", ["--weights", str(weights), "--size", str(SIZE), *tiny]),
                           ("onnx", ["--onnx", str(fp32)]), ("int8", ["--onnx", str(int8)])):
        flags = ["--runtime", "onnx"] if runtime != "jax" else []
        assert cli.main(["eval", "--model", "shuffle_yolov3", "--data", "street", "--split", "val", "--frames", "2",
                         "--json", *flags, *extra]) == 0
        scores[runtime] = json.loads(capsys.readouterr().out)
    assert scores["onnx"]["runtime"] == "onnx" and scores["onnx"]["protocol"] == "camera_voc"
    assert scores["onnx"]["mAP50"] == scores["jax"]["mAP50"] and scores["onnx"]["num_det"] == scores["jax"]["num_det"]
    assert scores["int8"]["classes_scored"] == list(STREET)
    onnx_eval = ["eval", "--model", "shuffle_yolov3", "--runtime", "onnx"]
    export = ["export", "--model", "shuffle_yolov3", "--weights", str(weights), "--out", str(tmp_path / "x")]
    for argv, message in (([*onnx_eval, "--onnx", str(fp32), "--size", "416"], "--size 416: the export"),
                          (["eval", "--model", "yolov3_darknet53", "--runtime", "onnx", "--onnx", str(fp32)],
                           "holds 'shuffle_yolov3', not --model 'yolov3_darknet53'"),
                          (onnx_eval, "--runtime onnx needs --onnx DIR"),
                          ([*export, "--size", "96", "--input-hw", "64,96"], "not both"),
                          ([*export, "--input-hw", "64,100"], "multiples of 32"),
                          ([*export, "--top-k", "5"], "--top-k applies to point-cloud")):
        with pytest.raises(SystemExit) as err:
            cli.main(argv)
        assert message in str(err.value)

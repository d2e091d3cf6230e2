"""RD export (YOLO-RD family): ONNX Runtime's decoded boxes and scores against the jitted JAX network,
its host post-processing against the compiled one, OrtRDPredictor against RDPredictor, and INT8
that runs with the decode left in float. Tiny 64 x 32 inputs (fit='resize') and stand-in weights."""

import functools
import json

import jax
import numpy as np
import pytest

from conftest import random_variables
from dsfec_jax import zoo
from dsfec_jax.data.rd.representations import RDRepresentation, representations
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.modalities.rd.ort import OrtRDPredictor
from dsfec_jax.modalities.rd.export import export_rd
from dsfec_jax.modalities.rd.quantize import quantize_rd
from dsfec_jax.modalities.rd.export import decoded_network
from dsfec_jax.models.yolo_rd.decode_host import NMS, TOP_K, host_detections
from dsfec_jax.modalities.rd.ort import check_input_size
from dsfec_jax.boxes.nms2d import detect_jax
from dsfec_jax.models.yolo_rd.decode import EVAL_CONF, EVAL_IOU, EVAL_MAX_DET
from dsfec_jax.models.yolo_rd.decode_v10 import top_detections
from dsfec_jax.modalities.rd.predict import RDPredictor

HW = (64, 32)
REP = RDRepresentation(fit="resize", input_hw=HW)
MAX_DET = 50
# YOLOv10n exports as cheaply but adds ~8 s of export and compile: its host top-k is checked below
# against the compiled one on synthetic arrays, and its ONNX parity by the command in the report
MODELS = ("yolov8n", "yolov8n_adapter")


@functools.cache
def compiled_postprocess(kind: str):
    """jit(vmap(one image's compiled post-processing)) at the evaluation settings: what decode.detect
    and decode_v10.detect_nms_free run after their decode (the reference of the host one)."""
    if kind == TOP_K:
        def one(boxes, scores):
            return top_detections(boxes, scores, EVAL_CONF, EVAL_MAX_DET)
    else:
        def one(boxes, scores):
            return detect_jax(boxes, scores, EVAL_IOU, EVAL_CONF, max_detections=EVAL_MAX_DET, multi_label=True)
    return jax.jit(jax.vmap(one))


@pytest.fixture(scope="module")
def samples():
    return load_rd_samples("synthetic", "val", 2, seed=3)


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """name -> (detector, variables, export dir, jitted decoded network); only yolov8n also writes
    the jax.export artifact."""
    out = {}
    for seed, name in enumerate(MODELS):
        det = zoo.create(name)
        variables = random_variables(det, seed)
        path = tmp_path_factory.mktemp(name)
        export_rd(det, variables, path, source={"command": "test"}, input_hw=HW, representation=REP,
                  jax_export=name == "yolov8n")
        network = jax.jit(lambda v, *maps, det=det: decoded_network(det, v)(*maps))  # variables as an argument
        out[name] = det, variables, path, functools.partial(network, variables)  # compile faster than as constants
    return out


def batch(det, samples) -> dict:
    maps = [representations(s, REP) for s in samples]
    return {k: np.stack([m[k] for m in maps]) for k in det.config.input_names}


@pytest.mark.parametrize("name", MODELS)
def test_onnx_decode_and_detections_match_jitted_jax(name, exports, samples):
    """Decoded boxes and scores to 1e-4 of their range; the final detections (host NMS on ONNX
    Runtime's outputs) equal the compiled post-processing's on JAX's (decode.detect's NMS)."""
    det, variables, path, reference = exports[name]
    predictor = OrtRDPredictor(path, max_detections=MAX_DET)
    inputs = batch(det, samples)
    boxes, scores = predictor.decoded(inputs)
    want_boxes, want_scores = reference(*(inputs[k] for k in det.config.input_names))
    assert boxes.shape == (2, 42, 4) and scores.shape == (2, 42, det.config.num_classes)
    assert np.abs(boxes - want_boxes).max() <= 1e-4 * np.abs(want_boxes).max()
    assert np.abs(scores - want_scores).max() <= 1e-4

    got = predictor.run(inputs)
    want = [np.asarray(a)[:, :MAX_DET] for a in compiled_postprocess(NMS)(want_boxes, want_scores)]
    np.testing.assert_array_equal(got[3], want[3])  # which slots hold a detection
    assert got[3].sum() >= 4, "too few detections to compare"
    np.testing.assert_array_equal(got[2], want[2])
    np.testing.assert_allclose(got[1], want[1], atol=1e-5)
    np.testing.assert_allclose(got[0], want[0], atol=1e-4 * np.abs(want[0]).max())


def test_manifest_and_jax_export_artifact(exports):
    det, _, path, _ = exports["yolov8n"]
    manifest = json.loads((path / "deploy.json").read_text())
    assert manifest["model"] == "yolov8n" and manifest["modality"] == "rd" and manifest["inputs"] == ["heat"]
    assert manifest["outputs"] == ["boxes", "scores"] and manifest["input_hw"] == list(HW)
    assert manifest["classes"] == list(det.config.classes) and manifest["config"]["arch"] == "v8"
    assert manifest["representation"]["fit"] == "resize" and manifest["postprocess"]["kind"] == NMS
    assert manifest["source"] == {"command": "test"} and manifest["versions"]["onnxruntime"]
    exported = jax.export.deserialize(bytearray((path / "model.jax_export").read_bytes()))
    assert [a.shape for a in exported.in_avals] == [(1, *HW, 3)]
    assert [a.shape for a in exported.out_avals] == [(1, 42, 4), (1, 42, 6)]


def test_the_export_runs_batch_norm_folded_into_the_convs(exports):
    """No BN's scale-and-shift after a conv: a conv's (Conv, or MatMul for a 1x1) output is never
    scaled or shifted by a constant (the SiLU's Mul reads two computed tensors)."""
    import onnx

    graph = onnx.load(str(exports["yolov8n"][2] / "model.onnx")).graph
    constants = {t.name for t in graph.initializer} | {o for n in graph.node if n.op_type == "Constant" for o in n.output}
    conv_outputs = {o for n in graph.node if n.op_type in ("Conv", "MatMul") for o in n.output}
    assert len(conv_outputs) >= 60 and "BatchNormalization" not in {n.op_type for n in graph.node}
    scaled = [n.name for n in graph.node if n.op_type in ("Sub", "Mul", "Div")
              and set(n.input) & conv_outputs and set(n.input) & constants]
    assert scaled == []


def test_ort_rd_predictor_equals_rd_predictor(exports, samples):
    det, variables, path, _ = exports["yolov8n_adapter"]
    ours = OrtRDPredictor(path).predict_samples(samples)
    ref = RDPredictor(det, variables, REP).predict_samples(samples)
    assert ours.keys() == ref.keys()
    for sid, want in ref.items():
        got = ours[sid]
        assert len(got) == len(want) > 0
        np.testing.assert_array_equal(got.names, want.names)
        np.testing.assert_allclose(got.scores, want.scores, atol=1e-5)
        np.testing.assert_allclose(got.xyxy, want.xyxy, atol=1e-3)


def test_int8_runs_with_the_decode_in_float(exports, samples, tmp_path):
    import onnx

    path = exports["yolov8n"][2]
    out = quantize_rd(path, tmp_path, load_rd_samples("synthetic", "train", 4), calibration="minmax")
    model = onnx.load(str(out["onnx"]))
    ops = [n.op_type for n in model.graph.node]
    assert ops.count("QuantizeLinear") >= 30 and "MatMul" in ops and "Conv" in ops
    consumers = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    below, frontier = set(), [n for n in model.graph.node if n.op_type == "Softmax"]  # the DFL's
    assert frontier
    while frontier:
        n = frontier.pop()
        below.add(n.op_type)
        frontier += [c for o in n.output for c in consumers.get(o, [])]
    assert "QuantizeLinear" not in below and "DequantizeLinear" not in below, below
    assert json.loads(out["manifest"].read_text())["quantization"]["calibration_frames"] == 4
    detections = OrtRDPredictor(tmp_path).predict_samples(samples)
    assert all(len(d) > 0 and np.isfinite(d.xyxy).all() and np.isfinite(d.scores).all() for d in detections.values())


@pytest.mark.parametrize("kind", [NMS, TOP_K])
def test_host_postprocessing_equals_the_compiled_one_with_ties(kind):
    """Scores on a coarse grid (many ties) and boxes in clusters (much suppression); TOP_K is
    YOLOv10's (decode_v10.top_detections)."""
    rng = np.random.default_rng(0)
    centres = rng.uniform(0, 60, (3, 120, 2)).round(-1)
    boxes = np.concatenate([centres, centres + rng.uniform(2, 12, (3, 120, 2))], -1).astype(np.float32)
    scores = (rng.integers(0, 20, (3, 120, 6)) / 20).astype(np.float32)
    got = host_detections(boxes, scores, kind, EVAL_IOU, EVAL_CONF, 300)
    want = [np.asarray(a) for a in compiled_postprocess(kind)(boxes, scores)]
    assert got[3].sum() >= 10
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


def test_bad_exports_and_inputs_are_refused_naming_what_was_expected(tmp_path):
    from dsfec_jax.modalities.rd.export import export_representation

    (tmp_path / "model.onnx").write_bytes(b"")
    (tmp_path / "deploy.json").write_text(json.dumps({"model": "dsfec_s", "modality": "points"}))
    with pytest.raises(ValueError, match="'points' model 'dsfec_s'; expected a 'rd' model's export"):
        OrtRDPredictor(tmp_path)
    with pytest.raises(ValueError, match=r"input 'heat' is \(256, 64\), the graph takes \(64, 32\)"):
        check_input_size({"input_hw": [64, 32]}, {"heat": np.zeros((1, 256, 64, 3))}, "m")
    with pytest.raises(ValueError, match="representation input_hw"):
        export_representation((256, 64), REP)
    with pytest.raises(ValueError, match="multiples of 32"):
        export_representation((250, 64), None)

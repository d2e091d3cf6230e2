"""`dsfec bench` times exactly the chain a predictor runs (issue 52): each modality's JAX chain is its
predictor's own stages (representation -> network + decode -> host NMS -> map pixels for an RD
map), named as the predictor names them, in the records and the report; the chain's output is the
predictor's. (The ONNX Runtime chains: tests/deploy/test_deploy.py's bench test, and the camera
chains of every runtime: tests/modalities/image/test_image_deploy.py.)"""

import numpy as np
import pytest

from conftest import random_variables, tiny
from dsfec_jax import zoo
from dsfec_jax.data.points.pillarize import select_columns
from dsfec_jax.data.points.sources import load_frames
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.deploy.bench import report, stages, workers
from dsfec_jax.modalities.points import bench as point_bench
from dsfec_jax.modalities.points.predict import Predictor
from dsfec_jax.modalities.rd import bench as rd_bench
from dsfec_jax.modalities.rd.predict import RDPredictor

RD_STAGES = ("representation", "network_decode", "nms", "to_map")
POINT_STAGES = ("pillarize", "network_decode", "nms")


def run(chain):
    x = None
    for _, fn in chain:
        x = fn(x)
    return x


@pytest.fixture(autouse=True)
def batch_one(monkeypatch):
    monkeypatch.setattr(stages, "JAX_BATCHES", (1,))  # the throughput's other batch sizes compile again


def test_the_rd_bench_times_the_rd_predictors_own_chain_and_names_its_stages(monkeypatch):
    det = zoo.create("yolov8n")
    variables = random_variables(det, 0)
    sample = load_rd_samples("synthetic", "test", 1, seed=0)[0]
    monkeypatch.setattr(rd_bench, "rd_model_setup", lambda name: (det, variables, "random", sample))
    (chain, fields), = rd_bench.rd_chains("yolov8n", ["jax"], 1, None, repeats=1).values()
    assert rd_bench.STAGES == RD_STAGES  # what the docs and readers name
    assert [s for s, _ in chain] == list(RD_STAGES) and fields["input_hw"] == [256, 64]
    # the host NMS (the predictor's default), not a compiled one: the nms stage's input is the
    # decoded candidates, its output the padded detections
    x = None
    for name, fn in chain:
        x = fn(x)
        if name == "network_decode":
            boxes, scores = x[0]  # (1, anchors, 4), (1, anchors, classes): every anchor's candidate
            assert boxes.shape == (1, 32 * 8 + 16 * 4 + 8 * 2, 4) and scores.shape == (*boxes.shape[:2], det.config.num_classes)
    want = RDPredictor(det, variables, constant_weights=True)(sample)  # as the bench makes it
    assert len(want) > 0 and len(x) == 1
    np.testing.assert_array_equal(x[0].xyxy, want.xyxy)
    np.testing.assert_array_equal(x[0].names, want.names)
    np.testing.assert_array_equal(x[0].scores, want.scores)
    # the worker's records and the report name the same stages
    records = workers.worker(["yolov8n"], ["jax"], 1, repeats=1, warmup=0, chains_of=lambda name: rd_bench.rd_chains)
    assert list(records[0]["stages_ms"]) == list(RD_STAGES)
    head = report.markdown(records).splitlines()[0]
    assert all(f"{s} ms" in head for s in RD_STAGES)


def test_the_point_bench_times_the_point_predictors_own_chain(monkeypatch):
    det = tiny("dsfec_s")
    variables = random_variables(det, 1)
    points = select_columns(load_frames("synthetic", "test", 1, seed=0)[0], det.config.point_features)
    monkeypatch.setattr(point_bench, "model_setup", lambda name: (det, variables, "random", points))
    (chain, fields), = point_bench.point_chains("dsfec_s", ["jax"], 1, None, repeats=1).values()
    assert [s for s, _ in chain] == list(POINT_STAGES) and point_bench.STAGES == POINT_STAGES
    got = run(chain)[0]
    want = Predictor(det, variables, score_threshold=0.1, constant_weights=True)(points)  # as the bench makes it
    assert len(want.scores) > 0 and fields["points"] == len(points)
    np.testing.assert_array_equal(got.scores, want.scores)
    np.testing.assert_array_equal(got.boxes.center, want.boxes.center)

"""The range-Doppler predictor and scoring: boxes come back in map pixels with class names and
descending scores, batching changes nothing, perfect detections score 100 and displaced ones 0,
and the RD sources refuse bad requests naming what was expected."""

import numpy as np
import pytest

from conftest import random_variables
from dsfec_jax import zoo
from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.data.rd.sources import NoSamples, load_rd_samples
from dsfec_jax.modalities.rd.evaluate import ground_truth, score_rd
from dsfec_jax.modalities.rd.predict import RDPredictor

CLASSES = zoo.config("yolov8n").classes


@pytest.fixture(scope="module")
def samples():
    return load_rd_samples("synthetic", "val", 3, seed=2)


def as_detections(gts: dict, shift: float = 0.0) -> dict:
    return {k: Boxes2D(b.xyxy + np.float32(shift), b.names, np.linspace(1, 0.6, len(b), dtype=np.float32))
            for k, b in gts.items()}


def test_perfect_detections_score_100_and_displaced_ones_0(samples):
    gts = ground_truth(samples)
    perfect = score_rd(gts, as_detections(gts), CLASSES)
    assert perfect["mAP50"] == perfect["mAP50_95"] == perfect["darod_mAP50"] == 100.0
    assert set(perfect["AP50"]) == {n for b in gts.values() for n in b.names}  # classes with ground truth only
    assert sum(perfect["num_gt"].values()) == sum(len(b) for b in gts.values())
    displaced = score_rd(gts, as_detections(gts, shift=1000.0), CLASSES)
    assert displaced["mAP50"] == displaced["mAP30"] == displaced["darod_mAP10"] == 0.0


def test_predictor_boxes_are_map_pixels_and_batching_changes_nothing(samples):
    det = zoo.create("yolov8n")
    # a small input keeps the compile cheap; fit='resize' scales the boxes back to the map
    predictor = RDPredictor(det, random_variables(det, 0), RDRepresentation(fit="resize", input_hw=(64, 32)),
                            score_threshold=0.0, max_detections=20)
    batched = predictor.predict_samples(samples, batch_size=3)
    h, w = samples[0].shape
    for s in samples:
        one = predictor(s)
        got = batched[s.sample_id]
        np.testing.assert_allclose(got.xyxy, one.xyxy, atol=1e-3)
        assert 0 < len(got) <= 20 and set(got.names) <= set(CLASSES)
        assert np.all(np.diff(got.scores) <= 0)
        assert got.xyxy.min() >= 0 and got.xyxy[:, [0, 2]].max() <= w and got.xyxy[:, [1, 3]].max() <= h


def test_point_models_are_refused_by_the_rd_predictor():
    with pytest.raises(ValueError, match="'rd' models; 'dsfec_s' is a 'points' model"):
        RDPredictor(zoo.create("dsfec_s"), {})


@pytest.mark.parametrize("data,split,count,match", [
    ("synthetic", "dev", 2, "splits are"), ("synthetic", "val", 0, "positive number"),
    ("radar:x", "val", 2, "expected one of"), ("raddet:/no/such/dir", "test", 2, "existing path")])
def test_rd_sources_refuse_bad_requests(data, split, count, match):
    with pytest.raises((NoSamples, ValueError, FileNotFoundError), match=match):
        load_rd_samples(data, split, count)


def test_host_and_compiled_postprocessing_give_the_same_detections(samples):
    det = zoo.create("yolov8n")
    variables, tiny = random_variables(det, 1), RDRepresentation(fit="resize", input_hw=(64, 32))
    host = RDPredictor(det, variables, tiny, max_detections=30).predict_samples(samples[:2])
    compiled = RDPredictor(det, variables, tiny, max_detections=30, postprocess="compiled").predict_samples(samples[:2])
    for k in host:
        np.testing.assert_array_equal(host[k].names, compiled[k].names)
        np.testing.assert_allclose(host[k].scores, compiled[k].scores, rtol=1e-5)
        np.testing.assert_allclose(host[k].xyxy, compiled[k].xyxy, atol=1e-3)

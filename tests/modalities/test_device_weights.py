"""Weights live on the device once loaded: the zoo's loaders and every predictor hold jax arrays, so
a jitted call does not convert every weight from numpy again (~20 us an array, issue 52)."""

import jax
import numpy as np

from conftest import random_variables, tiny
from dsfec_jax import api, zoo
from dsfec_jax.data.rd.batches import rd_eval_inputs
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.models.depth import TINY as TINY_DEPTH, init_variables
from dsfec_jax.modalities.image.depth import MonodepthPredictor
from dsfec_jax.modalities.image.predict import CameraPredictor
from dsfec_jax.modalities.points.predict import Predictor

CAMERA = {"widths": (16, 16, 32, 32, 64), "repeats": (1, 1, 1, 1, 1), "head_widths": (16, 32, 64), "head_units": 1}


def on_device(tree) -> bool:
    leaves = jax.tree.leaves(tree)
    return bool(leaves) and all(isinstance(x, jax.Array) and not isinstance(x, np.ndarray) for x in leaves)


def as_numpy(tree):
    return jax.tree.map(np.asarray, tree)


def test_loaders_and_predictors_hold_device_arrays():
    det = zoo.create("yolov8n")
    assert on_device(zoo.model_variables(det, zoo.shipped_weights("yolov8n")))
    points = tiny("dsfec_s")
    assert on_device(Predictor(points, as_numpy(random_variables(points, 0))).variables)
    camera = zoo.create("shuffle_yolov3", **CAMERA)
    assert on_device(CameraPredictor(camera, as_numpy(random_variables(camera, 1))).variables)
    depth = init_variables(TINY_DEPTH, jax.random.key(2))  # numpy leaves
    assert on_device(MonodepthPredictor(TINY_DEPTH, depth).variables)


def test_a_predictor_call_transfers_no_weight():
    """The second call of api.load's predictor, its input already on the device: nothing crosses from
    the host (numpy weights would, every call)."""
    rep = RDRepresentation(fit="resize", input_hw=(32, 32))
    predictor = api.load("yolov8n", predictor_options={"representation": rep})
    assert on_device(predictor.variables)
    sample = load_rd_samples("synthetic", "test", 1, seed=0)[0]
    inputs = jax.device_put({k: rd_eval_inputs(sample, rep, predictor.classes)[k] for k in predictor.input_names})
    first = predictor.run(inputs)
    with jax.transfer_guard_host_to_device("disallow"):
        again = predictor.run(inputs)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)


def test_a_deployed_predictor_compiles_its_weights_in_and_agrees_with_the_argument_form(monkeypatch):
    """constant_weights=True (api.load, the commands, the bench): the program takes the input alone,
    its stride-1 3x3 convs run as Winograd's products from kernels transformed once (the weights are
    known while tracing), and its detections are the argument form's to float rounding. A new
    assignment of variables drops the program."""
    from dsfec_jax.layers import winograd
    from dsfec_jax.modalities.rd.predict import RDPredictor

    rep = RDRepresentation(fit="resize", input_hw=(64, 32))
    det = zoo.create("yolov8n")
    variables = zoo.model_variables(det, zoo.shipped_weights("yolov8n"))
    sample = load_rd_samples("synthetic", "test", 1, seed=3)[0]
    inputs = {k: rd_eval_inputs(sample, rep, det.config.classes)[k] for k in det.config.input_names}
    calls = []
    transformed = winograd.conv3x3_transformed
    monkeypatch.setattr(winograd, "conv3x3_transformed", lambda *a: calls.append(a[1].shape) or transformed(*a))
    argument_form = RDPredictor(det, variables, rep)
    boxes, scores = argument_form.decoded(inputs)
    assert not calls  # kernels traced as arguments: XLA's conv
    deployed = RDPredictor(det, variables, rep, constant_weights=True)
    got_boxes, got_scores = deployed.decoded(inputs)
    assert calls and all(s[0] in (16, 36) for s in calls)
    assert api.load("yolov8n").constant_weights
    np.testing.assert_allclose(got_scores, scores, atol=1e-5)
    np.testing.assert_allclose(got_boxes, boxes, atol=1e-4 * np.abs(boxes).max())
    signature = next(line for line in deployed._with_weights.lower(inputs).as_text().splitlines() if "@main(" in line)
    assert signature.count("%arg") == len(inputs)  # the input arrays alone, no weight
    deployed.variables = variables
    assert deployed._with_weights is None

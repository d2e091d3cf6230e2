"""Shipped weights give the same detections on a fixed benchmark sample, one model per family
that ships weights: a refactor (issue 50's redesign moved every modality's pipeline) must not
change what a user's `api.load(name)(sample)` returns. Pinned: how many detections, the sum of
their box coordinates and of their scores (the digests of the redesign's before and after were
bit-identical for all seven shipped detectors; these sums leave room for XLA's last bits)."""

import numpy as np
import pytest

from dsfec_jax import api, zoo
from dsfec_jax.modalities.registry import modality_of

# model -> (detections, sum of box numbers, sum of scores) on the first test sample with an object, data seed 0
PINNED = {
    "dsfec_s": (37, 1611.8885, 6.416384),
    "yolov8n": (18, 5250.8657, 0.85930855),
    "shuffle_yolov3": (71, 43175.227, 7.395334),
}


def box_numbers(detections) -> np.ndarray:
    """The numbers of a point model's Detections (center, size, yaw, velocity) or a Boxes2D (xyxy)."""
    if hasattr(detections, "xyxy"):
        return np.asarray(detections.xyxy, np.float64)
    b = detections.boxes
    return np.concatenate([b.center, b.size, b.yaw[:, None], b.velocity], 1).astype(np.float64)


def first_test_sample(name: str):
    """The first test sample of the family's benchmark that holds an object (an empty map's
    digest, nothing found, would pin little)."""
    family = zoo.family_of(name)
    samples = modality_of(name).load_samples(family, family.benchmark, "test", 4, 0)
    return next(s for s in samples if len(s.boxes))


def summary(name: str) -> tuple[int, float, float]:
    sample = first_test_sample(name)
    found = api.load(name)(sample.points if zoo.family_of(name).points else sample)
    return len(found.scores), float(box_numbers(found).sum()), float(np.sum(found.scores, dtype=np.float64))


@pytest.mark.parametrize("name", sorted(PINNED))
def test_shipped_weights_detect_what_they_did(name):
    count, boxes, scores = summary(name)
    want = PINNED[name]
    assert count == want[0] and boxes == pytest.approx(want[1], rel=1e-5) and scores == pytest.approx(want[2], rel=1e-5)

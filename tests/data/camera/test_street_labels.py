"""Labels of the street benchmark: boxes are the visible extent of the object-id mask; the
occlusion, truncation and size rules drop objects or mark them difficult."""

import numpy as np
import pytest

from dsfec_jax.data.camera.street.generate import generate_frame, render_frame
from dsfec_jax.data.camera.street.labels import mask_extents, truncation
from dsfec_jax.data.camera.street.camera import PinholeCamera
from dsfec_jax.data.camera.street.world import Actor

from street_scenes import LANE, car, config, straight_world

KITTI_414 = config(camera="kitti", width=414)  # f = 240 px, 414 x 125


@pytest.fixture(scope="module")
def hand_built():
    """Ego at s = 50 in its lane. 0: a car 10 m ahead; 1: a car right behind it (hidden); 2: a car
    behind it shifted 2.1 m left (about 60 % hidden); 3: a car half out of the frame's right edge;
    4: a pedestrian 150 m away (about 3 px tall)."""
    ped = Actor(4, "pedestrian", 200.0, 23.25, size=(0.55, 0.35, 1.7), colors=((0.8, 0.2, 0.2),) * 4)
    world = straight_world([car(0, 60.0, LANE), car(1, 75.0, LANE), car(2, 75.0, 0.35), car(3, 65.0, -14.35), ped])
    return render_frame(world, KITTI_414)


def test_a_fully_occluded_object_is_dropped(hand_built):
    assert 1 not in hand_built.objects.id and not np.any(hand_built.instances == 1)
    assert hand_built.meta["dropped"]["occluded"] == 1


def test_a_partly_occluded_object_is_difficult(hand_built):
    k = list(hand_built.objects.id).index(2)
    assert 0.1 < hand_built.objects.visible_fraction[k] < 0.5
    assert hand_built.difficult[k] and hand_built.objects.truncation[k] == 0


def test_an_unoccluded_object_is_not_difficult(hand_built):
    k = list(hand_built.objects.id).index(0)
    assert hand_built.objects.visible_fraction[k] == 1 and not hand_built.difficult[k]
    # its box, by hand from its parts (bodies.parts, car 1.8 x 4.5 x 1.5 whose back is 7.75 m ahead):
    # widest, the body (1.74 m wide at 7.75 m); lowest, the rear axle's tyres touching the road
    # 0.58 m further; highest, the cabin's roof (its back 0.72 m further), 0.1 m above the camera
    cam, h = hand_built.camera, 1.4
    axle, cabin = 7.75 + 2.25 - (0.3 * 4.5 + 0.32), 7.75 + 2.25 - (0.06 + 0.28) * 4.5
    x1, y1, x2, y2 = hand_built.boxes.xyxy[k]
    x, y = lambda lateral, depth: cam.cx + cam.fx * lateral / depth, lambda down, depth: cam.cy + cam.fy * down / depth
    assert x1 == pytest.approx(x(-0.87, 7.75), abs=1) and x2 == pytest.approx(x(0.87, 7.75), abs=1)
    assert y1 == pytest.approx(y(h - 1.5, cabin), abs=1) and y2 == pytest.approx(y(h, axle), abs=1)


def test_an_object_cut_by_the_frame_edge_is_difficult(hand_built):
    k = list(hand_built.objects.id).index(3)
    assert hand_built.objects.visible_fraction[k] == 1 and hand_built.objects.truncation[k] > 0.3
    assert hand_built.difficult[k] and hand_built.boxes.xyxy[k, 2] == hand_built.camera.width


def test_a_tiny_object_is_dropped(hand_built):
    assert 4 not in hand_built.objects.id and np.any(hand_built.instances == 4)
    assert hand_built.meta["dropped"]["tiny"] == 1


def test_boxes_are_the_extent_of_the_object_mask():
    cfg = config(width=160)
    for index in range(3):
        frame = generate_frame(cfg, "train", index)
        assert len(frame.boxes) > 0
        w, h = frame.camera.width, frame.camera.height
        xyxy = frame.boxes.xyxy
        assert xyxy.min() >= 0 and np.all(xyxy[:, [0, 2]] <= w) and np.all(xyxy[:, [1, 3]] <= h)
        for oid, box in zip(frame.objects.id, xyxy):
            r, c = np.nonzero(frame.instances == oid)
            assert tuple(box) == (c.min(), r.min(), c.max() + 1, r.max() + 1)
        assert set(np.unique(frame.boxes.names)) <= set(cfg.classes)


def test_mask_extents_and_truncation_by_hand():
    mask = np.full((5, 6), -1)
    mask[1:3, 2:5] = 7
    mask[4, 0] = 3
    assert mask_extents(mask) == {3: (1, (0, 4, 1, 5)), 7: (6, (2, 1, 5, 3))}
    cam = PinholeCamera(10, 10, 5.0, 5.0, 5.0, 5.0)
    np.testing.assert_allclose(truncation(np.array([[2, 2, 6, 6], [5, 0, 15, 10], [np.nan] * 4]), cam), [0, 0.5, 1])

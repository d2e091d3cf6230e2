"""The street renderer's geometry: ground depth, stereo disparity, exact box rectangles, and the
batched box test against the one-by-one test."""

import math

import numpy as np
import pytest

from dsfec_jax.data.camera.street import render
from dsfec_jax.data.camera.street.camera import CAMERAS, PinholeCamera, camera_rotation
from dsfec_jax.data.camera.street.generate import generate_frame, render_frame
from dsfec_jax.data.camera.street.world import Actor

from street_scenes import car, config, straight_world


@pytest.mark.parametrize("camera", ["paper", "kitti"])
def test_flat_ground_depth_is_h_f_over_v_minus_cy(camera):
    cfg = config(camera=camera, width=96)
    frame = render_frame(straight_world(), cfg)
    cam = frame.camera
    v = np.arange(cam.height) + 0.5  # pixel centres
    below = v > cam.cy
    expected = cfg.camera_height_m * cam.fy / (v[below] - cam.cy)
    np.testing.assert_allclose(frame.depth[below], np.repeat(expected[:, None], cam.width, 1), rtol=2e-6)
    assert np.all(np.isinf(frame.depth[~below]))  # the sky: no surface, depth inf
    assert frame.instances.max() == -1 and len(frame.boxes) == 0


def test_pitch_down_moves_the_horizon_up():
    level = render_frame(straight_world(), config(width=64))
    pitched = render_frame(straight_world(), config(width=64, pitch_deg=5.0))
    assert np.isinf(pitched.depth).sum() < np.isinf(level.depth).sum()


def test_presets_follow_the_paper_and_kitti():
    paper, kitti = CAMERAS["paper"], CAMERAS["kitti"]
    assert paper.fx == pytest.approx(960 / math.tan(math.radians(60))) == pytest.approx(554.256, abs=1e-3)
    assert paper.hfov_deg == pytest.approx(120.0)
    assert (kitti.width, kitti.height, kitti.fx) == (1242, 375, 721.5377)
    small = paper.scaled(416)
    assert (small.width, small.height) == (416, 234) and small.hfov_deg == pytest.approx(120.0)


def test_a_point_at_depth_z_shifts_by_f_b_over_z_in_the_right_image():
    """A bus's back face is fronto-parallel at depth Z; with B chosen so that f B / Z = 4 pixels
    exactly, its pixels sit 4 columns further left in the right image, and the disparity computed
    from the depth map says 4 on them."""
    z_back, shift = 12.0, 4
    cam = CAMERAS["paper"].scaled(320)
    cfg = config(width=320, baseline_m=shift * z_back / cam.fx)
    bus = Actor(0, "bus", 50.0 + z_back + 6.0, -1.75, size=(2.55, 12.0, 3.1), colors=((0.2, 0.4, 0.7),))
    frame = render_frame(straight_world([bus]), cfg)
    face = (frame.instances == 0) & np.isclose(frame.depth, z_back, rtol=1e-5)
    r, c = np.nonzero(face)
    assert len(r) > 300 and np.all(c >= shift)
    np.testing.assert_allclose(frame.disparity()[face], shift, rtol=1e-4)
    agree = {k: np.mean(np.all(frame.image[r, c] == frame.right[r, c - k], axis=1)) for k in range(0, 9)}
    assert max(agree, key=agree.get) == shift and agree[shift] > 0.97, agree
    assert agree[shift - 1] < 0.9 and agree[shift + 1] < 0.9


def test_box_rectangles_hold_every_pixel_the_box_covers():
    cam = PinholeCamera(80, 60, 50.0, 50.0, 40.0, 30.0)
    rng = np.random.default_rng(0)
    for _ in range(20):
        center = rng.uniform([-4, -2, -1], [4, 2, 12], (1, 3))
        heading, pitch = rng.uniform(0, 2 * math.pi), rng.uniform(-0.3, 0.3)
        rot = camera_rotation(heading, pitch)[None]
        half = rng.uniform(0.2, 3.0, (1, 3))
        cp = render.CameraPrims(center, rot, half, np.zeros(1, np.int16), np.ones((1, 6), np.float32),
                                np.zeros(1, np.int32))
        hits = render.raycast(cp, cam, np.zeros(3), np.array([0.0, -1.0, 0.0]), 1e6, 0.1)
        r0, r1, c0, c1 = render.box_rects(center, rot, half, cam, np.zeros(3), 0.1)[0]
        covered = hits.prim == 0
        inside = np.zeros_like(covered)
        inside[r0:r1, c0:c1] = True
        assert not np.any(covered & ~inside)


def test_batched_box_tests_equal_one_by_one(monkeypatch):
    cfg = config(width=128)
    batched = generate_frame(cfg, "val", 1)
    monkeypatch.setattr(render, "BATCH_AREA", -1)  # every box on its own
    single = generate_frame(cfg, "val", 1)
    # the two paths round differently in float32 (scalars against arrays): equal to a few ulps
    np.testing.assert_allclose(batched.depth, single.depth, rtol=2e-6)
    assert np.mean(batched.instances == single.instances) > 0.999
    assert np.mean(np.abs(batched.image.astype(int) - single.image) <= 1) > 0.999
    np.testing.assert_array_equal(batched.boxes.names, single.boxes.names)
    np.testing.assert_allclose(batched.boxes.xyxy, single.boxes.xyxy, atol=1)


def test_nearer_boxes_win_the_depth_buffer():
    front, back = car(0, 60.0, -1.75), car(1, 64.0, -1.75)
    frame = render_frame(straight_world([back, front]), config(width=256))
    assert 0 in frame.objects.id and 1 not in frame.objects.id
    ahead = frame.instances >= 0
    np.testing.assert_allclose(frame.depth[ahead].min(), 60.0 - 2.25 - 50.0, rtol=1e-5)

"""geo.placement: depth from disparity, the lateral offset, ENU placement, reading a map at a box's
reference point, and objects of the synthetic drive placed with ground-truth depth."""

import math

import numpy as np
import pytest

from dsfec_jax.data.camera.street import StreetConfig, generate_drive
from dsfec_jax.geo.geodesy import geodetic_to_enu
from dsfec_jax.geo.placement import (BOTTOM_INSET, Placer, depth_from_disparity, frame_batch, lateral_offset,
                                     place_enu, reference_pixels, sample_at, windows)


def test_depth_from_disparity_reads_the_paper_as_b_f_over_a_d():
    """a = image width turns monodepth's width-fraction disparity into KITTI's 0.54 f / (W d);
    a = 1 takes a disparity in pixels; the two agree on the same pixel disparity."""
    f, w, b = 721.5377, 1242, 0.54
    d = np.array([0.1, 0.01, 0.0, -0.1, np.nan])
    depth = depth_from_disparity(d, b, f, a=w)
    assert depth[0] == pytest.approx(b * f / (w * 0.1)) and depth[1] == pytest.approx(10 * depth[0])
    assert depth[2] == math.inf and np.isnan(depth[3:]).all()
    assert depth_from_disparity(w * 0.1, b, f) == pytest.approx(depth[0])
    # the paper's literal a b f / d with a = 1367, f = 1012 would put a 0.1-width disparity 7.5e6 m away
    assert depth_from_disparity(0.1, 0.54, 1012, a=1367) == pytest.approx(0.54 * 1012 / 136.7)
    with pytest.raises(ValueError, match="must be > 0"):
        depth_from_disparity(d, 0.0, f)


def test_lateral_offset_and_placement_by_hand():
    assert lateral_offset(268.0, 20.0, cx=208.0, fx=120.0) == pytest.approx(10.0)
    assert lateral_offset(148.0, 20.0, cx=208.0, fx=120.0) == pytest.approx(-10.0)
    ego = (100.0, 200.0, 1.4)
    np.testing.assert_allclose(place_enu(10.0, 2.0, ego, 0.0), [102.0, 210.0, 1.4])                 # north
    np.testing.assert_allclose(place_enu(10.0, 2.0, ego, math.pi / 2), [110.0, 198.0, 1.4])         # east
    np.testing.assert_allclose(place_enu(10.0, 2.0, ego, math.pi), [98.0, 190.0, 1.4], atol=1e-12)  # south
    np.testing.assert_allclose(place_enu([10.0, 20.0], [0.0, 0.0], ego, math.radians(30))[:, :2],
                               [[105.0, 200 + 10 * math.cos(math.radians(30))],
                                [110.0, 200 + 20 * math.cos(math.radians(30))]])


def test_reference_pixels_and_the_window_median():
    boxes = np.array([[10.0, 20.0, 30.0, 60.0]])
    np.testing.assert_allclose(reference_pixels(boxes, "center"), [[20.0, 40.0]])
    np.testing.assert_allclose(reference_pixels(boxes, "bottom_center"), [[20.0, 60.0 - BOTTOM_INSET * 40]])
    with pytest.raises(ValueError, match="reference point"):
        reference_pixels(boxes, "top")
    m = np.full((80, 50), 7.0)
    m[40, 20] = 1000.0                                   # one outlier pixel: the median ignores it
    m[38:43, 18] = np.inf                                # sky pixels are not values
    assert sample_at(m, [[20.5, 40.5]], radius=2)[0] == 7.0
    assert sample_at(m, [[20.5, 40.5]], radius=0)[0] == 1000.0
    m[60:, :] = 50.0                                     # the road below the box
    assert sample_at(m, [[20.0, 59.9]], boxes, radius=2)[0] == 7.0   # clipped to the box: no road
    assert sample_at(m, [[20.0, 60.9]], None, radius=2)[0] == 50.0     # unclipped, a pixel lower: road
    assert np.isnan(sample_at(np.full((4, 4), np.inf), [[1.0, 1.0]])[0])


def test_placer_skips_what_has_no_depth_and_builds_the_exchange_format():
    depth = np.full((40, 60), np.inf)
    depth[10:30, 10:20] = 12.0
    placer = Placer(fx=50.0, cx=30.0, origin=(49.0, 8.4, 115.0))
    objects, ok = placer.place([[10, 10, 20, 30], [40, 0, 50, 5]], ["car", "pedestrian"], [0.9, 0.5], depth,
                               (0.0, 0.0, 1.4), 0.0)
    assert ok.tolist() == [True, False] and len(objects) == 1
    o = objects[0]
    assert set(o) == {"class", "score", "box", "depth_m", "x_m", "lat", "lon", "alt"}
    assert o["depth_m"] == 12.0 and o["x_m"] == pytest.approx((15 - 30) * 12 / 50)
    np.testing.assert_allclose(geodetic_to_enu(o["lat"], o["lon"], o["alt"], (49.0, 8.4, 115.0)),
                               [o["x_m"], 12.0, 1.4], atol=1e-6)
    batch = frame_batch("dev-01", "000042", 1.7e9, {"lat": 49.0, "lon": 8.4, "alt": 115.0, "heading_deg": 0.0},
                        objects)
    assert batch["batch_id"] == "dev-01:000042" and batch["objects"] == objects


@pytest.fixture(scope="module")
def frames():
    cfg = StreetConfig(render_right=False)
    drive = generate_drive(cfg, "test", 0, num_frames=41)
    return cfg, [drive.frame(j) for j in (0, 20, 40)]


def test_objects_placed_at_their_true_depth_land_on_their_centres(frames):
    """The formulas inverted exactly: the projected centre at its true depth is the centre."""
    cfg, fs = frames
    for f in fs:
        c = f.objects.center_cam
        u = f.camera.cx + f.camera.fx * c[:, 0] / c[:, 2]
        enu = place_enu(c[:, 2], lateral_offset(u, c[:, 2], f.camera.cx, f.camera.fx), f.ego.enu, f.ego.heading_rad)
        np.testing.assert_allclose(enu[:, :2], f.objects.center_enu[:, :2], atol=1e-6)


@pytest.mark.parametrize("reference", ["center", "bottom_center"])
def test_ground_truth_depth_places_objects_within_their_footprint(frames, reference):
    """Where most of the read window shows the object itself, the median depth is that of a
    point of its surface, which lies inside its 3D box: within half its horizontal diagonal of
    its centre in depth; laterally the read is off by at most the window's reach, radius + 1
    pixels at that depth. (Measured on 4 drives: never more than 0.05 m beyond half the diagonal.)
    Occluded reads (the window shows the occluder) and see-through ones are left out."""
    cfg, fs = frames
    checked = 0
    for f in fs:
        placer = Placer(f.camera.fx, f.camera.cx, cfg.origin, reference)
        objects, ok = placer.place(f.boxes.xyxy, f.boxes.names, np.ones(len(f.boxes)), f.depth, f.ego.enu,
                                   f.ego.heading_rad)
        assert ok.all()
        uv = reference_pixels(f.boxes.xyxy, reference)
        for k, (rows, cols) in enumerate(windows(f.depth.shape, uv, f.boxes.xyxy, placer.radius)):
            if np.mean(f.instances[rows, cols] == f.objects.id[k]) <= 0.5:
                continue
            o = objects[k]
            enu = geodetic_to_enu(o["lat"], o["lon"], o["alt"], cfg.origin)
            err = np.hypot(*(enu[:2] - f.objects.center_enu[k, :2]))
            half_diag = 0.5 * np.hypot(*f.objects.size[k, :2])
            assert err <= half_diag + (placer.radius + 1) * o["depth_m"] / f.camera.fx, (f.frame_id, k, o)
            checked += 1
    assert checked >= 10


import numpy as np
import pytest

from dsfec_jax.boxes import pixor
from dsfec_jax.boxes.geometry import points_in_boxes
from dsfec_jax.data.points.augment import AugmentConfig, augment, flip_y, rotate, scale, wrap_angle
from dsfec_jax.data.points.frame import Boxes, Frame
from dsfec_jax.data.points.pillarize import PillarSpec, pillarize, pillarize_frames
from dsfec_jax.models.dsfec.targets import detector_targets, head_targets
from dsfec_jax.core.grid import Grid
from dsfec_jax.models.dsfec.net import RADAR_FEATURES

GRID = Grid((0.0, 8.0), (-4.0, 4.0), (-2.0, 2.0), 1.0)  # 8 x 8 cells


def spec(p=4, n=2):
    return PillarSpec(GRID, ("x", "y", "z", "rcs"), p, n)


def test_pillarize_places_points_and_counts_every_drop():
    pts = np.array([
        [0.5, -3.5, 0, 1], [0.6, -3.6, 0, 2], [0.7, -3.7, 0, 3],  # cell (0,0): 3 points, 1 over N=2
        [5.2, 1.1, 0, 4],                                          # cell (5,5)
        [9.0, 0.0, 0, 5], [1.0, 0.0, 3.0, 6],                      # outside x / outside z
        [np.nan, 0, 0, 7],                                         # non-finite
    ], np.float32)
    tensors, stats = pillarize(pts, spec())
    assert stats == {"points": 7, "kept": 3, "dropped_nonfinite": 1, "dropped_outside_grid": 2,
                     "dropped_pillar_limit": 0, "dropped_point_limit": 1, "pillars": 2}
    assert tensors["coords"].tolist()[:2] == [[0, 0], [5, 5]] and tensors["coords"][2:].tolist() == [[-1, -1]] * 2
    np.testing.assert_array_equal(tensors["mask"][:2], [[True, True], [True, False]])
    np.testing.assert_allclose(tensors["points"][0, :, 3], [1, 2])  # first-come points of the cell kept
    np.testing.assert_allclose(tensors["points"][1, 0], pts[3])
    assert stats["kept"] + sum(v for k, v in stats.items() if k.startswith("dropped")) == stats["points"]


def test_pillar_limit_keeps_the_densest_pillars():
    pts = np.array([[0.5, -3.5, 0, 0]] * 1 + [[2.5, -3.5, 0, 0]] * 3 + [[4.5, -3.5, 0, 0]] * 2, np.float32)
    tensors, stats = pillarize(pts, spec(p=2, n=4))
    assert tensors["coords"].tolist() == [[2, 0], [4, 0]]
    assert stats["dropped_pillar_limit"] == 1 and stats["kept"] == 5


def test_empty_frame_is_valid():
    tensors, stats = pillarize(np.zeros((0, 4), np.float32), spec())
    assert not tensors["mask"].any() and (tensors["coords"] == -1).all() and stats["kept"] == 0


def test_pillarize_frames_checks_feature_names():
    frame = Frame(np.zeros((3, 3), np.float32), ("x", "y", "z"), Boxes.empty(), "f0", "test")
    with pytest.raises(KeyError, match="rcs"):
        pillarize_frames([frame], spec())


def boxes(*rows, names=None):
    rows = np.array(rows, np.float32)  # x, y, z, w, l, h, yaw, vx, vy
    names = np.array(names or ["car"] * len(rows))
    return Boxes(rows[:, 0:3], rows[:, 3:6], rows[:, 6], rows[:, 7:9], names)


def test_pixor_encode_decode_is_identity():
    rng = np.random.default_rng(0)
    centre, size = rng.uniform(-40, 40, (100, 2)), rng.uniform(0.3, 12, (100, 2))
    yaw, cell = rng.uniform(-np.pi, np.pi, 100), rng.uniform(-40, 40, (100, 2))
    c2, s2, y2 = pixor.decode(pixor.encode(centre, size, yaw, cell), cell)
    np.testing.assert_allclose(c2, centre, atol=1e-9)
    np.testing.assert_allclose(s2, size, rtol=1e-9)
    np.testing.assert_allclose(np.cos(y2 - yaw), 1.0, atol=1e-9)


def test_targets_decode_back_to_the_boxes():
    b = boxes([3.2, 0.7, 0, 1.8, 4.0, 1.5, 0.3, 0, 0], [6.5, -2.5, 0, 0.6, 0.6, 1.7, 0.0, 0, 0],
              names=["car", "pedestrian"])
    t = detector_targets(b, {"car": ("car",), "vru": ("pedestrian", "bicycle")}, GRID, 1)
    car, vru = t["car"], t["vru"]
    assert car["cls"].shape == (8, 8, 1) and car["box"].shape == (8, 8, 6)
    assert car["reg_mask"].sum() >= 4 and vru["reg_mask"].sum() == 1  # a 0.6 m pedestrian still gets its cell
    assert vru["cls"][6, 1].tolist() == [1.0, 0.0]
    cells = pixor.cell_centres(GRID, 1)
    for head, idx in ((car, 0), (vru, 1)):
        centre, size, yaw = pixor.decode(head["box"][head["reg_mask"]], cells[head["reg_mask"]])
        np.testing.assert_allclose(centre, np.repeat(b.center[idx : idx + 1, :2], len(centre), 0), atol=1e-5)
        np.testing.assert_allclose(size, np.repeat(b.size[idx : idx + 1, :2], len(size), 0), rtol=1e-5)
        np.testing.assert_allclose(yaw, b.yaw[idx], atol=1e-6)


def test_overlapping_boxes_give_cells_to_the_nearest_centre():
    b = boxes([2.5, 0.5, 0, 2, 4, 1.5, 0, 0, 0], [4.5, 0.5, 0, 2, 4, 1.5, 0, 0, 0])
    t = head_targets(b, ("car",), GRID, 1)
    dx = t["box"][..., 2]
    assert t["reg_mask"][3, 4] and abs(dx[3, 4] - (2.5 - 3.5)) < 1e-6  # nearest of the two is at x=2.5
    assert t["reg_mask"][4, 4] and abs(dx[4, 4]) < 1e-6


def frame_with_points(rng):
    b = boxes([20, 5, 0, 2, 4.5, 1.6, 0.4, 3, 1], [40, -10, 0.2, 0.7, 0.7, 1.8, -1.0, 0, 1.2],
              names=["car", "pedestrian"])
    pts = []
    for c, s, y in zip(b.center, b.size, b.yaw):
        local = rng.uniform(-0.45, 0.45, (30, 3)) * s[[1, 0, 2]]
        xy = local[:, :2] @ np.array([[np.cos(y), -np.sin(y)], [np.sin(y), np.cos(y)]]).T + c[:2]
        pts.append(np.column_stack([xy, local[:, 2] + c[2], rng.normal(size=(30, 4))]))
    pts.append(np.column_stack([rng.uniform(0, 80, (50, 2)), rng.uniform(-1, 1, (50, 5))]))
    pts = np.concatenate(pts).astype(np.float32)
    return Frame(pts, RADAR_FEATURES, b, "aug", "test")


@pytest.mark.parametrize("op", [flip_y, lambda f: rotate(f, 0.7), lambda f: scale(f, 1.1),
                                lambda f: augment(f, AugmentConfig(point_dropout=0.0), np.random.default_rng(3))])
def test_boxes_move_with_the_points(op):
    frame = frame_with_points(np.random.default_rng(0))
    out = op(frame)
    before = points_in_boxes(frame.points[:, :3], frame.boxes.center, frame.boxes.size, frame.boxes.yaw)
    after = points_in_boxes(out.points[:, :3], out.boxes.center, out.boxes.size, out.boxes.yaw)
    np.testing.assert_array_equal(before, after)
    assert before[:30, 0].all() and before[30:60, 1].all()  # the membership test is not vacuous


def test_velocities_follow_the_transform():
    frame = frame_with_points(np.random.default_rng(1))
    flipped = flip_y(frame)
    np.testing.assert_allclose(flipped.boxes.velocity[:, 1], -frame.boxes.velocity[:, 1])
    np.testing.assert_allclose(flipped.column("vy_comp"), -frame.column("vy_comp"))
    np.testing.assert_allclose(flipped.boxes.yaw, wrap_angle(-frame.boxes.yaw), atol=1e-6)
    rotated = rotate(frame, np.pi / 2)
    np.testing.assert_allclose(rotated.boxes.velocity[0], [-1, 3], atol=1e-5)
    np.testing.assert_allclose(np.hypot(rotated.column("vx_comp"), rotated.column("vy_comp")),
                               np.hypot(frame.column("vx_comp"), frame.column("vy_comp")), rtol=1e-5)


def test_point_dropout_drops_about_the_rate():
    frame = frame_with_points(np.random.default_rng(2))
    out = augment(frame, AugmentConfig(flip_prob=0, rotation=0, scale=(1, 1), point_dropout=0.5),
                  np.random.default_rng(0))
    assert 0.3 * len(frame.points) < len(out.points) < 0.7 * len(frame.points)
    assert len(out.boxes) == len(frame.boxes)


def test_centerpoint_radius_and_gaussian_heatmap():
    import math
    from dsfec_jax.models.radarnext.targets import draw_gaussian, gaussian_kernel, gaussian_radius, heatmap_radius

    # by hand, 4 x 2 cells at min_overlap 0.1: r1 = (6 + sqrt(36 - 4 * 7.2/1.1)) / 2 = 4.567,
    # r2 = (12 + sqrt(144 - 16 * 7.2)) / 2 = 8.683, r3 = (-1.2 + sqrt(1.44 + 1.6 * 7.2)) / 2 = 1.2
    assert gaussian_radius(4, 2) == pytest.approx(1.2)
    assert heatmap_radius(4, 2) == 2  # floored, at least 2
    assert heatmap_radius(40, 20) == int(gaussian_radius(40, 20)) > 2
    g = gaussian_kernel(2)
    sigma = 5 / 6
    assert g.shape == (5, 5) and g[2, 2] == 1.0 and np.allclose(g, g.T) and np.allclose(g, g[::-1])
    assert g[2, 3] == pytest.approx(math.exp(-1 / (2 * sigma**2)))
    hm = np.zeros((6, 7), np.float32)
    draw_gaussian(hm, 0, 6, 2)  # corner: clipped, peak kept
    assert hm[0, 6] == 1.0 and hm[0, 4] == pytest.approx(g[2, 0]) and hm[3:, :].sum() == 0
    draw_gaussian(hm, 1, 5, 2)  # overlap combines by maximum, not sum
    assert hm.max() == 1.0 and hm[1, 5] == 1.0 and hm[0, 6] == 1.0
    with pytest.raises(ValueError, match="outside"):
        draw_gaussian(hm, 6, 0, 2)

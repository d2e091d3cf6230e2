"""DSFEC head targets: the bounded-cell search equals the all-cells-against-all-boxes definition."""

import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.boxes import pixor
from dsfec_jax.boxes.geometry import points_in_boxes
from dsfec_jax.boxes.structures import Boxes
from dsfec_jax.data.points.sources import load_frames
from dsfec_jax.models.dsfec.targets import cell_owners, head_targets

CLASSES = ("pedestrian", "bicycle")


def all_pairs_owners(flat, b: Boxes, grid, stride: int, shape) -> tuple[np.ndarray, np.ndarray]:
    """The definition, cell by box: every cell centre tested against every box footprint."""
    h, w = shape
    cell_pts = np.concatenate([flat, np.zeros((len(flat), 1))], 1)
    z0 = np.zeros((len(b), 3))
    z0[:, :2] = b.center[:, :2]
    inside = points_in_boxes(cell_pts, z0, np.concatenate([b.size[:, :2], np.ones((len(b), 1))], 1), b.yaw)
    step = grid.cell * stride
    ci = np.floor((b.center[:, 0] - grid.x_range[0]) / step).astype(int)
    cj = np.floor((b.center[:, 1] - grid.y_range[0]) / step).astype(int)
    on_map = (ci >= 0) & (ci < h) & (cj >= 0) & (cj < w)
    inside[(ci * w + cj)[on_map], np.nonzero(on_map)[0]] = True
    dist = np.where(inside, np.linalg.norm(flat[:, None, :] - b.center[None, :, :2], axis=-1), np.inf)
    cells = np.nonzero(np.isfinite(dist.min(axis=1)))[0]
    return cells, dist.argmin(axis=1)[cells]


def assert_owners_equal(boxes: Boxes, classes, grid, stride: int) -> int:
    """cell_owners == all_pairs_owners on the boxes of `classes`; -> the number of positives."""
    b = boxes.select(np.isin(boxes.names, classes))
    if len(b) == 0:  # head_targets returns empty maps before it asks
        return 0
    centres = pixor.cell_centres(grid, stride)
    flat, shape = centres.reshape(-1, 2), centres.shape[:2]
    got, want = cell_owners(flat, b, grid, stride, shape), all_pairs_owners(flat, b, grid, stride, shape)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    return len(got[0])


def random_boxes(rng, grid, m: int) -> Boxes:
    """Boxes of every size class over and beyond the grid, many overlapping, some on cell edges."""
    (x0, x1), (y0, y1) = grid.x_range, grid.y_range
    center = np.zeros((m, 3), np.float32)
    center[:, 0] = rng.uniform(x0 - 3, x1 + 3, m)
    center[:, 1] = rng.uniform(y0 - 3, y1 + 3, m)
    center[: m // 4, :2] = np.round(center[: m // 4, :2] / grid.cell) * grid.cell  # on cell edges
    size = rng.uniform([0.4, 0.4, 1.0], [3.0, 12.0, 3.0], (m, 3)).astype(np.float32)
    yaw = rng.uniform(-np.pi, np.pi, m).astype(np.float32)
    yaw[: m // 5] = rng.choice([0.0, np.pi / 2, np.pi / 4, -np.pi], m // 5)
    names = rng.choice(np.array(CLASSES + ("car",)), m)
    return Boxes(center, size, yaw, np.zeros((m, 2), np.float32), names)


@pytest.mark.parametrize("stride", [1, 2])
def test_targets_equal_the_all_pairs_definition_on_random_boxes(stride):
    grid = zoo.config("dsfec_s").grid
    rng = np.random.default_rng(0)
    for m in (1, 3, 12, 40):
        assert_owners_equal(random_boxes(rng, grid, m), CLASSES, grid, stride)


def test_targets_equal_the_all_pairs_definition_on_synthetic_windows():
    det = zoo.create("dsfec_l")
    positives = 0
    for frame in load_frames("synthetic", "train", 4, seed=3):
        for classes in det.config.head_classes:
            positives += assert_owners_equal(frame.boxes, tuple(classes), det.config.grid, det.config.output_stride)
    assert positives > 100  # the frames do exercise the positives


def test_a_cell_shared_by_two_boxes_goes_to_the_nearer_centre():
    grid = zoo.config("dsfec_s").grid
    x, y = grid.x_range[0] + 10.25, grid.y_range[0] + 10.25  # a cell centre at stride 1
    boxes = Boxes(np.array([[x + 0.9, y, 0], [x - 0.6, y, 0]], np.float32), np.full((2, 3), 3.0, np.float32),
                  np.zeros(2, np.float32), np.zeros((2, 2), np.float32), np.array(["pedestrian", "bicycle"]))
    t = head_targets(boxes, CLASSES, grid, 1)
    i, j = int((x - grid.x_range[0]) / grid.cell), int((y - grid.y_range[0]) / grid.cell)
    np.testing.assert_array_equal(t["cls"][i, j], [0.0, 1.0])  # the bicycle's centre is 0.6 m away, the pedestrian's 0.9

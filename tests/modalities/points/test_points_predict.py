import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import api, zoo
from dsfec_jax.boxes.decode import decode_heads
from dsfec_jax.boxes.nms import batched_rotated_nms
from dsfec_jax.boxes.pixor import cell_centres
from dsfec_jax.data.points.pillarize import pillarize
from dsfec_jax.boxes.structures import Boxes
from dsfec_jax.models.dsfec.targets import detector_targets
from dsfec_jax.core.grid import Grid
from dsfec_jax.modalities.points.predict import Predictor
from conftest import tiny
from builders import toy_frame

GRID = Grid((0.0, 16.0), (-8.0, 8.0), (-2.5, 2.5), 0.5)
HEADS = {"car": ("car",), "truck": ("truck",), "vru": ("pedestrian", "bicycle")}


def test_perfect_head_maps_decode_to_the_ground_truth():
    gt = Boxes(np.array([[4, -3, 0], [11, 3, 0], [13, -5, 0]], np.float32),
               np.array([[1.8, 4.2, 1.5], [2.5, 8.0, 3.0], [0.6, 0.6, 1.7]], np.float32),
               np.array([0.2, -0.4, 0.0], np.float32), np.zeros((3, 2), np.float32),
               np.array(["car", "truck", "pedestrian"]))
    t = detector_targets(gt, HEADS, GRID, 2)
    # A perfect network: confident exactly where targets are positive, with exact box codes.
    outputs = {h: {"cls": jnp.asarray(np.where(v["cls"] > 0, 8.0, -8.0))[None], "box": jnp.asarray(v["box"])[None]}
               for h, v in t.items()}
    boxes, scores, labels = jax.device_get(decode_heads(outputs, HEADS, cell_centres(GRID, 2), top_k=64))
    keep = batched_rotated_nms(boxes[0].astype(np.float64), scores[0], labels[0], 0.2, score_threshold=0.5)
    got = sorted((int(labels[0][k]), *np.round(boxes[0][k], 4)) for k in keep)
    names = ["car", "truck", "pedestrian", "bicycle"]
    want = sorted((names.index(n), c[0], c[1], s[0], s[1], y) for n, c, s, y in zip(gt.names, gt.center, gt.size, gt.yaw))
    assert len(got) == 3
    np.testing.assert_allclose(np.array(got), np.array(want), atol=1e-4)


def test_predictor_from_points_and_frames():
    det = tiny("dsfec_s")
    predictor = Predictor(det, det.init(jax.random.key(0)), score_threshold=0.0, top_k=20, max_boxes=30)
    frame = toy_frame(np.random.default_rng(0), det.config.grid)
    a = predictor(frame)
    b = predictor(frame.points)  # same columns as the model's point_features
    assert len(a.boxes) == len(a.scores) <= 30
    assert set(a.boxes.names) <= {"car", "truck", "pedestrian", "bicycle"}
    np.testing.assert_allclose(a.scores, b.scores)
    assert (np.diff(a.scores) <= 1e-7).all()  # sorted by score
    # An empty cloud (or one with no point on the grid) is reported as nothing, at any threshold,
    # although the network itself answers an all-zero canvas with bias-only candidates.
    for cloud in (np.zeros((0, 7), np.float32), np.array([[-50.0, 0, 0, 0, 0, 0, 0]], np.float32)):
        empty = predictor(cloud)
        assert len(empty.scores) == 0 and len(empty.boxes) == 0 and empty.boxes.center.shape == (0, 3)
    tensors = pillarize(np.zeros((0, 7), np.float32), predictor.spec)[0]
    raw = predictor.predict_tensors({k: v[None] for k, v in tensors.items()})[0]
    assert len(raw.scores) > 0 and np.isfinite(raw.scores).all()


def edge_distance(boxes, grid) -> np.ndarray:
    """Metres from each box centre to the nearest edge of the grid."""
    x, y = boxes.center[:, 0], boxes.center[:, 1]
    return np.min([x - grid.x_range[0], grid.x_range[1] - x, y - grid.y_range[0], grid.y_range[1] - y], axis=0)


@pytest.mark.parametrize("name", sorted(p.stem for p in zoo.WEIGHTS_DIR.glob("*.msgpack")
                                         if zoo.family_of(p.stem).modality == "points"))
def test_shipped_weights_detect_nothing_inside_the_grid_on_an_empty_cloud(name):
    """Measured (default threshold 0.1, full grid): in the interior an empty cloud leaves
    bias-only logits (centre-cell scores <= 0.03), but within 2 m of the grid's edge the 'SAME'
    zero padding breaks that constant and the trained Car head answers with up to 0.15: DSFEC-S
    59 edge 'cars', L 12, Baseline 3, M 2. On real frames top-k keeps most of them out (DSFEC-S:
    1.5 per synthetic test frame). This pins the interior clean and the artefact to the edge
    (a +2 shift of the Car logits' bias puts detections 23 m inside: the test fails)."""
    cfg = zoo.config(name)
    cells = cfg.grid.shape[0] * cfg.grid.shape[1] // cfg.output_stride**2  # decode every cell: top-k
    predictor = api.load(name, max_pillars=64, predictor_options={"top_k": cells})  # must not hide one
    grid = predictor.detector.config.grid
    assert len(predictor(np.zeros((0, 7), np.float32)).scores) == 0  # the predictor reports nothing
    tensors = pillarize(np.zeros((0, 7), np.float32), predictor.spec)[0]
    out = predictor.predict_tensors({k: v[None] for k, v in tensors.items()})[0]  # what the network answers
    assert np.isfinite(out.scores).all() and (out.scores < 0.2).all()
    assert (edge_distance(out.boxes, grid) < 2.0).all(), np.round(out.boxes.center[:, :2], 1)


def test_predictor_runs_on_the_fewest_slots_that_hold_the_frame():
    """A sparse frame runs on a small slot bucket with the same detections as on every slot, and
    each bucket compiles once; a frame that fills more slots takes a larger bucket."""
    from dsfec_jax.data.points.sources import load_frames
    from dsfec_jax.data.points.pillarize import select_columns
    from dsfec_jax.modalities.points.predict import SLOT_BUCKET, decoded_network, fewest_slots

    predictor = api.load("dsfec_s", max_pillars=8 * SLOT_BUCKET)
    frame = load_frames("synthetic", "test", 1)[0]
    sparse = predictor(frame)
    tensors = pillarize(select_columns(frame, predictor.spec.features), predictor.spec)[0]
    batch = {k: v[None] for k, v in tensors.items()}
    used, cut = int(batch["mask"].any(-1).sum()), fewest_slots(batch)["mask"].shape[1]
    assert used <= cut < batch["mask"].shape[1] and (cut == SLOT_BUCKET or cut < 2 * used)
    # every slot, no bucketing: the same boxes and scores
    network = decoded_network(predictor.detector, 100)  # with the weights compiled in, as api.load's predictor runs
    decoded = jax.device_get(jax.jit(lambda b: network(predictor.variables, b))(batch))
    want = predictor._postprocess(decoded[0][0], decoded[1][0], decoded[2][0])
    np.testing.assert_array_equal(sparse.scores, want.scores)
    np.testing.assert_array_equal(sparse.boxes.center, want.boxes.center)
    # more occupied slots than one bucket: the next one, all pillars kept
    crowded = {**batch, "mask": batch["mask"].copy()}
    crowded["mask"][0, : SLOT_BUCKET + 1, 0] = True
    assert fewest_slots(crowded)["mask"].shape[1] == 2 * SLOT_BUCKET
    crowded["mask"][0, :, 0] = True
    assert fewest_slots(crowded) is crowded
    # slots not packed first (a caller's own tensors): the last occupied slot decides
    scattered = {**batch, "mask": np.zeros_like(batch["mask"])}
    scattered["mask"][0, 3 * SLOT_BUCKET - 1, 0] = True
    assert fewest_slots(scattered)["mask"].shape[1] == 4 * SLOT_BUCKET

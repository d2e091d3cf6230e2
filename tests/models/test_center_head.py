"""CenterHead targets, decoding and losses (RadarNeXt), and one training step."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.boxes.center_decode import decode_center_head
from dsfec_jax.boxes.structures import Boxes
from dsfec_jax.models.radarnext.targets import center_head_targets
from dsfec_jax.core.grid import Grid
from dsfec_jax.models.radarnext.loss import axis_aligned_diou, center_head_loss, cornernet_focal_loss, decode_at

GRID = Grid((0.0, 10.24), (-5.12, 5.12), (-3.0, 2.0), 0.16)  # 64 x 64 cells, maps 32 x 32 at stride 2
CLASSES = ("pedestrian", "bicycle", "car")


def boxes(*rows):
    """rows of (name, x, y, z, w, l, h, yaw)."""
    a = np.array([r[1:] for r in rows], np.float32).reshape(-1, 7)
    return Boxes(a[:, :3], a[:, 3:6], a[:, 6], np.zeros((len(rows), 2), np.float32),
                 np.array([r[0] for r in rows], dtype="<U16"))


SCENE = boxes(("car", 5.0, 1.0, -0.5, 1.8, 4.2, 1.5, 0.3), ("pedestrian", 2.05, -3.0, 0.1, 0.6, 0.7, 1.7, -1.0),
              ("truck", 8.0, 3.0, 0.0, 2.5, 7.0, 3.0, 0.0), ("car", 30.0, 0.0, 0.0, 1.8, 4.2, 1.5, 0.0))


def test_targets_place_peaks_offsets_and_codes():
    t = center_head_targets(SCENE, CLASSES, GRID, 2)
    assert t["hm"].shape == (32, 32, 3) and t["corner_hm"].shape == (32, 32, 1)
    assert t["mask"].sum() == 2  # the truck is not a class here, the far car is off the map
    step = 0.32
    i, j = int(5.0 / step), int((1.0 + 5.12) / step)
    assert t["hm"][i, j, 2] == 1.0 and t["hm"][:, :, 2].max() == 1.0
    assert t["ind"][0] == i * 32 + j
    np.testing.assert_allclose(t["box"][0], [5.0 / step - i, 6.12 / step - j, -0.5, np.log(1.8), np.log(4.2),
                                             np.log(1.5), np.sin(0.3), np.cos(0.3)], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(t["gt_box"][0], [5.0, 1.0, -0.5, 1.8, 4.2, 1.5, 0.3], rtol=1e-6)
    assert t["hm"][:, :, 1].max() == 0.0  # no bicycle in the scene
    # the car's front edge midpoint (2.1 m ahead along yaw 0.3) gets a corner peak
    fi, fj = int((5.0 + 2.1 * np.cos(0.3)) / step), int((6.12 + 2.1 * np.sin(0.3)) / step)
    assert t["corner_hm"][fi, fj, 0] == 1.0 and t["corner_hm"][i, j, 0] == 1.0


def test_targets_keep_peaks_beyond_max_objects():
    many = boxes(*[("pedestrian", 1.0 + 0.8 * k, 0.0, 0.0, 0.6, 0.7, 1.7, 0.0) for k in range(10)])
    t = center_head_targets(many, CLASSES, GRID, 2, max_objects=4)
    assert t["mask"].sum() == 4 and (t["hm"][:, :, 0] == 1.0).sum() == 10


def perfect_outputs(t):
    """Head maps that encode the targets exactly (logit of the heatmap, codes at centre cells)."""
    h, w, _ = t["hm"].shape
    maps = {"hm": jnp.log(np.clip(t["hm"], 1e-6, 1 - 1e-6) / (1 - np.clip(t["hm"], 1e-6, 1 - 1e-6)))}
    code = np.zeros((h * w, 8), np.float32)
    code[t["ind"][t["mask"]]] = t["box"][t["mask"]]
    code = code.reshape(h, w, 8)
    maps.update(reg=code[..., 0:2], height=code[..., 2:3], dim=code[..., 3:6], rot=code[..., 6:8],
                iou=np.ones((h, w, 1), np.float32),
                corner_hm=jnp.log(np.clip(t["corner_hm"], 1e-6, 1 - 1e-6) / (1 - np.clip(t["corner_hm"], 1e-6, 1 - 1e-6))))
    return {k: jnp.asarray(v)[None] for k, v in maps.items()}


def test_decoding_inverts_the_targets():
    t = center_head_targets(SCENE, CLASSES, GRID, 2)
    out = perfect_outputs(t)
    boxes_, scores, labels = decode_center_head(out, GRID, 2, top_k=2)
    order = np.argsort(-np.asarray(labels[0]))  # car (2) first, then pedestrian (0)
    np.testing.assert_allclose(np.asarray(boxes_[0])[order], t["gt_box"][:2], atol=2e-5)
    np.testing.assert_allclose(scores[0], 1.0, atol=1e-5)
    # a lower IoU prediction lowers the score as s^0.5 * ((iou + 1) / 2)^0.5
    out["iou"] = jnp.zeros_like(out["iou"])
    assert np.allclose(decode_center_head(out, GRID, 2, top_k=2)[1][0], np.sqrt(0.5), atol=1e-5)


def test_cornernet_focal_loss_by_hand():
    target = jnp.array([[1.0, 0.5, 0.0]])
    logits = jnp.array([[0.0, 0.0, -2.0]])
    p = jax.nn.sigmoid(logits)[0]
    want = -(np.log(0.5) * 0.5**2 + np.log(1 - p[1]) * p[1] ** 2 * 0.5**4 + np.log(1 - p[2]) * p[2] ** 2)
    loss, npos = cornernet_focal_loss(logits, target)
    assert npos == 1 and float(loss) == pytest.approx(float(want), rel=1e-5)


def test_diou_of_identical_boxes_is_one_and_falls_with_distance():
    box = jnp.array([[1.0, 2.0, 0.0, 1.8, 4.2, 1.5, 0.7]])
    assert float(axis_aligned_diou(box, box)[0]) == pytest.approx(1.0)
    far = box.at[0, 0].add(10.0)
    assert float(axis_aligned_diou(far, box)[0]) < 0  # disjoint: IoU 0 minus the distance term


def test_losses_are_small_for_perfect_maps_and_decode_matches_targets():
    t = center_head_targets(SCENE, CLASSES, GRID, 2)
    batch = {k: jnp.asarray(v)[None] for k, v in t.items()}
    cfg = zoo.config("radarnext_pan", grid=GRID)
    loss, parts = center_head_loss(perfect_outputs(t), batch, cfg)
    assert parts["box"] < 1e-5 and parts["diou"] < 1e-4 and parts["iou"] < 1e-3 and parts["corner"] < 1e-6
    decoded = decode_at(batch["box"], batch["ind"], 32, 0.32, jnp.array([[0.0, -5.12]]))
    np.testing.assert_allclose(decoded[0, :2], t["gt_box"][:2], atol=2e-5)
    noisy = dict(perfect_outputs(t), hm=jnp.zeros((1, 32, 32, 3)))
    assert center_head_loss(noisy, batch, cfg)[1]["hm"] > parts["hm"] + 1.0


def test_loss_gradient_is_finite_on_an_all_zero_map():
    """A nearly empty training window gives head maps of exact zeros at padding slots: the yaw
    decode (atan2 of sin = cos = 0) must not put NaN into the gradient (it did: step 1 NaN)."""
    t = center_head_targets(SCENE, CLASSES, GRID, 2)
    batch = {k: jnp.asarray(v)[None] for k, v in t.items()}
    cfg = zoo.config("radarnext_pan", grid=GRID)
    zeros = {k: jnp.zeros_like(v) for k, v in perfect_outputs(t).items()}
    grads = jax.grad(lambda out: center_head_loss(out, batch, cfg)[0])(zeros)
    assert all(bool(jnp.isfinite(g).all()) for g in jax.tree.leaves(grads))
    assert float(jnp.abs(grads["rot"]).max()) > 0  # the real objects still pull on the yaw codes


def test_fit_trains_radarnext_on_windows_including_empty_ones(tmp_path, uncompiled_init):
    """The whole path: 4D frames -> windowed CenterHead batches (origin inputs, one compiled
    step; some 32-cell windows of this narrow field of view hold no point at all) -> VoD metric."""
    import json

    from dsfec_jax.data.points.sources import load_frames
    from dsfec_jax.modalities.points.fit import fit
    from dsfec_jax.train.schedules import get_schedule

    frames = load_frames("synthetic4d", "train", 4, features="native")
    val = load_frames("synthetic4d", "val", 1, features="native")
    overrides = dict(grid=GRID, max_pillars=96, layer_nums=(1, 1, 1))
    _, state, scores = fit(zoo.config("radarnext_mdfen", **overrides), frames, val, get_schedule("radarnext", batch_size=2),
                           tmp_path, steps=4, window=32, eval_every=4, progress=False)
    logged = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    losses = [row["loss"] for row in logged if "loss" in row]
    assert losses and all(np.isfinite(losses))
    assert int(state["step"]) == 4 and set(scores) >= {"mAP", "mAP_corridor", "AP", "num_gt"}
    assert len(json.loads((tmp_path / "run.json").read_text())["windows"]) == 4

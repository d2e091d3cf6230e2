"""Builders shared by test modules in different folders (importable like conftest: pytest puts
tests/ on sys.path when it loads tests/conftest.py). Test modules never import each other."""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax
import numpy as np

from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.points import nuscenes as nu
from dsfec_jax.data.points.frame import Boxes, Frame
from dsfec_jax.metrics import submission as sub
from dsfec_jax.models.dsfec.net import RADAR_FEATURES

# --------------------------------------------------------------------------- nuScenes tables (hand-checked)

SQ = np.sqrt(0.5)
Q_YAW90, Q_YAW180, Q_ID = (SQ, 0, 0, SQ), (0, 0, 0, 1), (1, 0, 0, 0)


def radar_rows(*points) -> np.ndarray:
    """Rows of (x, y, rcs, vx_comp, vy_comp, invalid_state) as 18-field radar points (ambig_state 3)."""
    out = np.zeros((len(points), 18))
    for row, (x, y, rcs, vx, vy, invalid) in zip(out, points):
        row[[0, 1, 5, 8, 9, 14]] = x, y, rcs, vx, vy, invalid
        row[11] = 3
    return out


def build_tiny_nuscenes(root: Path) -> Path:
    """Three samples 0.5 s apart; RADAR_FRONT (key frame + one earlier sweep) and RADAR_BACK_LEFT.

    Reference ego pose (LIDAR_TOP key frame of s1): at (10, 20, 0), yawed +90 deg.
    """
    tables = root / "v1.0-mini"
    tables.mkdir(parents=True)
    files = {"front": "samples/RADAR_FRONT/n0__RADAR_FRONT__1500000.pcd",
             "front_prev": "sweeps/RADAR_FRONT/n0__RADAR_FRONT__1450000.pcd",
             "back": "samples/RADAR_BACK_LEFT/n0__RADAR_BACK_LEFT__1520000.pcd"}
    for f in files.values():
        (root / f).parent.mkdir(parents=True, exist_ok=True)
    nu.write_radar_pcd(root / files["front"], radar_rows((2, 0, 5, 1, 0, 0), (7, 7, 1, 0, 0, 1)), pad_to=2000)
    nan_row = radar_rows((np.nan, 0, 0, 0, 0, 0))
    nu.write_radar_pcd(root / files["front_prev"], np.concatenate([radar_rows((2, 0, 6, 1, 0, 0)), nan_row]))
    nu.write_radar_pcd(root / files["back"], radar_rows((3, 1, 8, 0.5, 0, 0)))
    t = {
        "sample": [{"token": "s0", "timestamp": 1_000_000, "prev": "", "next": "s1"},
                   {"token": "s1", "timestamp": 1_500_000, "prev": "s0", "next": "s2"},
                   {"token": "s2", "timestamp": 2_000_000, "prev": "s1", "next": ""}],
        "sensor": [{"token": "sen_l", "channel": "LIDAR_TOP", "modality": "lidar"},
                   {"token": "sen_f", "channel": "RADAR_FRONT", "modality": "radar"},
                   {"token": "sen_b", "channel": "RADAR_BACK_LEFT", "modality": "radar"}],
        "calibrated_sensor": [
            {"token": "cs_l", "sensor_token": "sen_l", "translation": [0, 0, 1.8], "rotation": Q_ID},
            {"token": "cs_f", "sensor_token": "sen_f", "translation": [1, 0, 0.5], "rotation": Q_YAW90},
            {"token": "cs_b", "sensor_token": "sen_b", "translation": [-1, 0, 0], "rotation": Q_YAW180}],
        "ego_pose": [{"token": "ep_ref", "timestamp": 1_500_000, "translation": [10, 20, 0], "rotation": Q_YAW90},
                     {"token": "ep_f", "timestamp": 1_500_000, "translation": [10, 20, 0], "rotation": Q_YAW90},
                     {"token": "ep_fp", "timestamp": 1_450_000, "translation": [9, 20, 0], "rotation": Q_YAW90},
                     {"token": "ep_b", "timestamp": 1_520_000, "translation": [10, 20, 0], "rotation": Q_YAW90}],
        "sample_data": [
            {"token": "sd_l", "sample_token": "s1", "ego_pose_token": "ep_ref", "calibrated_sensor_token": "cs_l",
             "timestamp": 1_500_000, "is_key_frame": True, "filename": "samples/LIDAR_TOP/x.bin",
             "prev": "", "next": ""},
            {"token": "sd_f", "sample_token": "s1", "ego_pose_token": "ep_f", "calibrated_sensor_token": "cs_f",
             "timestamp": 1_500_000, "is_key_frame": True, "filename": files["front"], "prev": "sd_fp", "next": ""},
            {"token": "sd_fp", "sample_token": "s1", "ego_pose_token": "ep_fp", "calibrated_sensor_token": "cs_f",
             "timestamp": 1_450_000, "is_key_frame": False, "filename": files["front_prev"], "prev": "",
             "next": "sd_f"},
            {"token": "sd_b", "sample_token": "s1", "ego_pose_token": "ep_b", "calibrated_sensor_token": "cs_b",
             "timestamp": 1_520_000, "is_key_frame": True, "filename": files["back"], "prev": "", "next": ""}],
        "category": [{"token": "c_car", "name": "vehicle.car"}, {"token": "c_ped", "name": "human.pedestrian.adult"},
                     {"token": "c_dog", "name": "animal"}],
        "instance": [{"token": "i_car", "category_token": "c_car"}, {"token": "i_ped", "category_token": "c_ped"},
                     {"token": "i_dog", "category_token": "c_dog"}],
        "sample_annotation": [
            {"token": f"a{k}", "sample_token": f"s{k}", "instance_token": "i_car", "translation": [11 + k, 25, 1],
             "size": [2, 4.5, 1.5], "rotation": Q_YAW180, "prev": f"a{k - 1}" if k else "",
             "next": f"a{k + 1}" if k < 2 else ""} for k in range(3)] + [
            {"token": "p1", "sample_token": "s1", "instance_token": "i_ped", "translation": [10, 21, 0.9],
             "size": [0.6, 0.7, 1.8], "rotation": Q_ID, "prev": "", "next": ""},
            {"token": "d1", "sample_token": "s1", "instance_token": "i_dog", "translation": [10, 22, 0.3],
             "size": [0.3, 0.8, 0.5], "rotation": Q_ID, "prev": "", "next": ""}],
    }
    for name, records in t.items():
        (tables / f"{name}.json").write_text(json.dumps(records))
    return root


# --------------------------------------------------------------------------- detector frames


def toy_frame(rng, grid):
    """Two cars and a pedestrian with points on them, plus clutter."""
    names = np.array(["car", "car", "pedestrian"])
    centre = np.array([[4.0, -3.0, 0.0], [10.0, 3.0, 0.0], [13.0, -5.0, 0.0]], np.float32)
    size = np.array([[1.8, 4.2, 1.5], [1.9, 4.6, 1.6], [0.6, 0.6, 1.7]], np.float32)
    boxes = Boxes(centre, size, np.array([0.2, -0.4, 0.0], np.float32), np.zeros((3, 2), np.float32), names)
    pts = [np.column_stack([c[:2] + rng.normal(0, 0.4, (12, 2)), rng.normal(0, 0.3, 12), np.full((12, 4), 1.0)])
           for c in centre]
    clutter = np.column_stack([rng.uniform(0, 16, (20, 1)), rng.uniform(-8, 8, (20, 1)), np.zeros((20, 5))])
    return Frame(np.concatenate(pts + [clutter]).astype(np.float32), RADAR_FEATURES, boxes, "toy", "test")


# --------------------------------------------------------------------------- nuScenes submission boxes


def box(tok, x, y, score=None, name="car"):
    b = {"sample_token": tok, "translation": [float(x), float(y), 0.0], "size": [1.9, 4.5, 1.6],
         "rotation": sub.yaw_to_quaternion(0.0), "velocity": [0.0, 0.0], "detection_name": name,
         "attribute_name": ""}
    if score is not None:
        b["detection_score"] = float(score)
    return b


def random_scene(n_samples=12, seed=0):
    """Cars with noisy detections, misses and false alarms, so every threshold gives a different AP."""
    rng = np.random.default_rng(seed)
    gt, pred = {}, {}
    for s in range(n_samples):
        tok = f"s{s}"
        centres = rng.uniform(-30, 30, size=(rng.integers(0, 6), 2))
        gt[tok] = [box(tok, x, y) for x, y in centres]
        hits = [c + rng.normal(0, 1.2, 2) for c in centres if rng.random() < 0.8]
        alarms = list(rng.uniform(-30, 30, size=(rng.integers(0, 4), 2)))
        pred[tok] = [box(tok, x, y, rng.random()) for x, y in hits + alarms]
    return gt, pred


BOXES2D_CLASSES = ("car", "person", "truck")


def boxes2d_scene(n_images=24, seed=0, sloppiness=1.0):
    """2D ground truth and detections (sample id -> Boxes2D): jittered copies of most boxes (some
    sloppy enough to miss at high IoU; `sloppiness` scales the jitter), random false positives, one
    class absent from most images, scores with ties."""
    rng = np.random.default_rng(seed)
    gts, dets = {}, {}
    for i in range(n_images):
        k = int(rng.integers(0, 5))
        xy = rng.uniform(0, 200, (k, 2))
        wh = rng.uniform(10, 60, (k, 2))
        gt = np.concatenate([xy, xy + wh], 1).astype(np.float32)
        names = rng.choice(BOXES2D_CLASSES[:2] if i % 5 else BOXES2D_CLASSES, k)
        keep = rng.random(k) < 0.8
        jitter = rng.normal(0, sloppiness * rng.choice([1.0, 6.0]), (k, 4)).astype(np.float32)
        det = gt[keep] + jitter[keep]
        det = np.concatenate([np.minimum(det[:, :2], det[:, 2:]), np.maximum(det[:, :2], det[:, 2:])], 1)
        fp_xy = rng.uniform(0, 200, (int(rng.integers(0, 4)), 2))
        fp = np.concatenate([fp_xy, fp_xy + 20], 1).astype(np.float32)
        det_names = np.concatenate([names[keep], rng.choice(BOXES2D_CLASSES, len(fp))])
        scores = np.round(rng.uniform(0.05, 1, len(det_names)), 2).astype(np.float32)  # rounding: ties
        gts[f"img{i:03d}"] = Boxes2D(gt, names)
        dets[f"img{i:03d}"] = Boxes2D(np.concatenate([det, fp]).astype(np.float32), det_names, scores)
    return gts, dets


# --------------------------------------------------------------------------- a tiny model in child processes

# Imported at start-up by every Python process that finds it on PYTHONPATH: registers `tiny_s`
# (conftest.tiny's dsfec_s) with an init that compiles nothing (slow, and not what the tests of
# a CLI's processes are about), so the real entry points and their worker processes run in seconds.
# An init that compiles nothing: the variables of init's shapes, filled with small random values.
QUICK_INIT = """
import jax
import numpy as np

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid

_init = zoo.Detector.init


def quick_init(self, rng):
    gen = np.random.default_rng(0)

    def fill(path, leaf):
        low, high = (0.5, 1.5) if path[-1].key == "var" else (-0.1, 0.1)
        return jax.numpy.asarray(gen.uniform(low, high, leaf.shape), leaf.dtype)

    return jax.tree_util.tree_map_with_path(fill, jax.eval_shape(lambda r: _init(self, r), rng))


zoo.Detector.init = quick_init
"""
TINY_MODEL_SITE = QUICK_INIT + """
zoo.REGISTRY["tiny_s"] = zoo.create("dsfec_s", name="tiny_s", max_pillars=96, max_points=4,
    grid=Grid(x_range=(0.0, 16.0), y_range=(-8.0, 8.0), z_range=(-2.5, 2.5), cell=0.5)).config
"""


def tiny_model_pythonpath(folder: Path) -> str:
    """PYTHONPATH for child processes that know `tiny_s` (TINY_MODEL_SITE, written into FOLDER)."""
    (folder / "sitecustomize.py").write_text(TINY_MODEL_SITE)
    return os.pathsep.join([str(folder)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])


def tensorboard_events(run_dir):
    """The event files of a run directory read back with TensorBoard's own reader (every scalar and
    image kept)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    reader = EventAccumulator(str(run_dir), size_guidance={"scalars": 0, "images": 0})
    reader.Reload()
    return reader


def assert_rows_are_the_batch_rows(stream, step: int, rows: slice) -> None:
    """`stream.batch(step, rows)` (a process's share of a global batch, train/parallel.py) holds
    exactly those rows of the whole batch; per-step inputs (a subnet's masks) whole."""
    from dsfec_jax.train.parallel import PER_STEP_INPUTS

    whole, part = stream.batch(step), stream.batch(step, rows)
    per_step = set(whole.get(PER_STEP_INPUTS, ()))
    assert part["inputs"].keys() == whole["inputs"].keys() and part["window"] == whole["window"]
    for key, value in whole["inputs"].items():
        cut = (lambda a: a) if key in per_step else (lambda a: a[rows])
        jax.tree.map(lambda w, p: np.testing.assert_array_equal(cut(np.asarray(w)), p), value, part["inputs"][key])
    jax.tree.map(lambda w, p: np.testing.assert_array_equal(np.asarray(w)[rows], p), whole["targets"], part["targets"])

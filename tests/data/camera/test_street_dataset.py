"""The street benchmark's splits, determinism, config round trip and PNG + NPZ cache."""

import dataclasses
import json

import numpy as np
import pytest

from dsfec_jax.data.camera.street import StreetConfig, StreetDataset, generate_drive, generate_frame
from dsfec_jax.data.camera.street.cache import StreetCachedDataset, open_cache, read_manifest, write_cache

from street_scenes import TINY


def assert_same_frame(a, b):
    for name in ("image", "right", "depth", "instances"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(a.boxes.xyxy, b.boxes.xyxy)
    np.testing.assert_array_equal(a.boxes.names, b.boxes.names)
    np.testing.assert_array_equal(a.boxes.difficult, b.boxes.difficult)
    for f in dataclasses.fields(a.objects):
        np.testing.assert_array_equal(getattr(a.objects, f.name), getattr(b.objects, f.name))
    assert a.ego == b.ego and a.camera == b.camera and a.frame_id == b.frame_id


def test_same_split_index_and_seed_give_identical_frames():
    assert_same_frame(generate_frame(TINY, "train", 3), generate_frame(TINY, "train", 3))


def test_other_index_seed_or_split_give_other_frames():
    base = generate_frame(TINY, "train", 3)
    for other in (generate_frame(TINY, "train", 4), generate_frame(TINY, "train", 3, seed=1),
                  generate_frame(TINY, "val", 3)):
        assert not np.array_equal(base.image, other.image)
        assert base.ego.enu != other.ego.enu


def test_splits_draw_their_worlds_from_disjoint_areas():
    east = {s: [generate_drive(TINY, s, i, num_frames=1).poses()[0].enu[0] for i in range(4)] +
            [generate_frame(TINY, s, i).ego.enu[0] for i in range(2)] for s in ("train", "val", "test")}
    assert max(east["train"]) < min(east["val"]) and max(east["val"]) < min(east["test"])


def test_frames_hold_every_field_issue_25_needs():
    frame = generate_frame(TINY, "val", 0)
    h, w = frame.camera.height, frame.camera.width
    assert (w, h) == (64, 36) and frame.image.dtype == np.uint8 and frame.right.shape == (h, w, 3)
    assert frame.depth.dtype == np.float32 and frame.depth.shape == (h, w)
    assert len(frame.objects) == len(frame.boxes) and frame.objects.center_cam.shape == (len(frame.boxes), 3)
    np.testing.assert_allclose(frame.objects.center_enu[:, 2], frame.objects.size[:, 2] / 2, rtol=1e-6)
    no_right = generate_frame(dataclasses.replace(TINY, render_right=False), "val", 0)
    assert no_right.right is None
    np.testing.assert_array_equal(no_right.depth, frame.depth)


def test_config_round_trips_through_json():
    cfg = dataclasses.replace(StreetConfig(), camera="kitti", width=200, lanes_per_direction=(2,))
    assert StreetConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    with pytest.raises(ValueError, match="camera"):
        StreetConfig(camera="fisheye")


def test_dataset_indexes_like_a_sequence():
    data = StreetDataset(TINY, "val", 0, 3)
    assert len(data) == 3 and data[-1].frame_id == "street-val-s0-000002"
    with pytest.raises(IndexError):
        data[3]


def test_cache_writes_pngs_and_npz_and_reads_them_back(tmp_path):
    data = StreetDataset(TINY, "val", 0, 2)
    write_cache(data, tmp_path)
    manifest = read_manifest(tmp_path)
    assert manifest["images"] == ["street_000000.png", "street_000001.png"]
    assert manifest["right_images"][1] == "street_000001_right.png" and manifest["camera"]["width"] == 64
    cached = StreetCachedDataset(tmp_path, TINY, "val", 0)
    assert len(cached) == 2
    for i in range(2):
        a, b = cached[i], data[i]
        assert_same_frame(a, b)
        assert a.gps.time_s.tolist() == b.gps.time_s.tolist() and a.meta == b.meta


def test_cache_refuses_damage_and_rebuilds_for_another_config(tmp_path):
    write_cache(StreetDataset(TINY, "val", 0, 1), tmp_path)
    (tmp_path / "street_000000_right.png").unlink()
    with pytest.raises(ValueError, match="image files missing"):
        StreetCachedDataset(tmp_path)
    (tmp_path / "street_000000_right.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="street_000000_right.png: not a readable PNG"):
        StreetCachedDataset(tmp_path)[0]
    other = dataclasses.replace(TINY, baseline_m=0.3)
    rebuilt = open_cache(tmp_path, other, "val", 0, 1)
    assert rebuilt.cfg == other and rebuilt[0].baseline_m == 0.3

"""Real-format readers: nuScenes radar PCD + JSON tables, View-of-Delft and TJ4DRadSet (KITTI layout).

Real samples are read by path from the shared data folder (non-commercial licences: never copied);
the nuScenes table fixture is built here, in a temp dir, with hand-computed expected values.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dsfec_jax.boxes.geometry import box_point_counts, points_in_boxes
from dsfec_jax.data.points import kitti
from dsfec_jax.data.points import nuscenes as nu
from builders import Q_YAW90, build_tiny_nuscenes, radar_rows  # the hand-checked nuScenes fixture

FUZZ = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
PCD_HEADER_BYTES, PCD_ROW_BYTES, PCD_POINTS = 370, 43, 125


def pcd_files(shared_data) -> list[Path]:
    return sorted((shared_data / "nuscenes_radar").glob("*.pcd"))


def raises_naming(path, fn, *args):
    with pytest.raises(ValueError) as info:
        fn(path, *args)
    assert Path(path).name in str(info.value), str(info.value)
    return str(info.value)


def read_or_valueerror(fn, path, *args):
    """A fuzzed file either parses or raises ValueError naming the file: nothing else, never a hang."""
    try:
        return fn(path, *args)
    except ValueError as e:
        assert Path(path).name in str(e), str(e)
        return None


# --------------------------------------------------------------------------- nuScenes PCD


def struct_rows(path) -> list[tuple]:
    """Independent decoding with struct (the devkit's way) to check the numpy reader against."""
    raw = Path(path).read_bytes()
    fmt = "<fffbhfffffbbbbbbbb"
    assert struct.calcsize(fmt) == PCD_ROW_BYTES
    return [struct.unpack_from(fmt, raw, PCD_HEADER_BYTES + i * PCD_ROW_BYTES) for i in range(PCD_POINTS)]


def test_real_pcd_matches_struct_decoding_and_devkit_filters(shared_data):
    kept = []
    for path in pcd_files(shared_data):
        pcd = nu.read_radar_pcd(path)
        assert pcd.dtype.names == nu.RADAR_FIELDS and len(pcd) == PCD_POINTS
        rows = np.array(struct_rows(path), np.float64)
        np.testing.assert_array_equal(np.stack([pcd[f].astype(np.float64) for f in nu.RADAR_FIELDS], 1), rows)
        assert np.all(pcd["z"] == 0) and nu.drop_nonfinite(pcd)[1] == 0
        # devkit defaults: invalid_state in [0], dyn_prop in 0..6, ambig_state in [3]
        by_hand = (rows[:, 14] == 0) & (rows[:, 3] <= 6) & (rows[:, 11] == 3)
        kept.append(len(nu.filter_radar_points(pcd)))
        assert kept[-1] == by_hand.sum()
        assert len(nu.filter_radar_points(pcd, range(18), range(8), range(5))) == PCD_POINTS
    assert kept == [69, 70]


def test_pcd_features_in_sensor_frame(shared_data):
    pcd = nu.filter_radar_points(nu.read_radar_pcd(pcd_files(shared_data)[0]))
    feats = nu.radar_features(pcd, dt=0.25)
    assert feats.shape == (69, 7) and feats.dtype == np.float32
    np.testing.assert_array_equal(feats[:, 3], pcd["rcs"])
    np.testing.assert_array_equal(feats[:, 4:6], np.stack([pcd["vx_comp"], pcd["vy_comp"]], 1))
    assert np.all(feats[:, 6] == 0.25)


def random_pcd(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pts = np.zeros((n, 18))
    pts[:, :3] = rng.uniform(-50, 50, (n, 3))
    pts[:, 3], pts[:, 11], pts[:, 14] = rng.integers(0, 8, n), rng.integers(0, 5, n), rng.integers(0, 18, n)
    pts[:, 5:10] = rng.normal(size=(n, 5))
    return pts


def test_pcd_write_read_round_trip_ignores_padding(tmp_path):
    pts = random_pcd(40)
    path = tmp_path / "a.pcd"
    nu.write_radar_pcd(path, pts, pad_to=9471)
    assert path.stat().st_size == 9471
    back = nu.read_radar_pcd(path)
    np.testing.assert_allclose(np.stack([back[f] for f in nu.RADAR_FIELDS], 1), pts, atol=1e-5)
    nu.write_radar_pcd(tmp_path / "b.pcd", back)
    assert (tmp_path / "b.pcd").read_bytes() == path.read_bytes()[:(tmp_path / "b.pcd").stat().st_size]


def test_pcd_errors_name_the_file(tmp_path, shared_data):
    good = pcd_files(shared_data)[0].read_bytes()
    path = tmp_path / "bad.pcd"
    path.write_bytes(good.replace(b"DATA binary", b"DATA ascii!"))
    assert "expected 'binary'" in raises_naming(path, nu.read_radar_pcd)
    path.write_bytes(good.replace(b" vy_rms\n", b"\n"))
    assert "expected the 18" in raises_naming(path, nu.read_radar_pcd)
    path.write_bytes(good[:PCD_HEADER_BYTES + 10 * PCD_ROW_BYTES])
    assert "truncated" in raises_naming(path, nu.read_radar_pcd)
    path.write_bytes(good[:200])
    assert "DATA" in raises_naming(path, nu.read_radar_pcd)
    path.write_bytes(good.replace(b"POINTS 125", b"POINTS 124"))
    raises_naming(path, nu.read_radar_pcd)


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@FUZZ
@given(cut=st.integers(0, 9471))
def test_pcd_truncation_fails_cleanly_or_reads_all_points(shared_data, fuzz_dir, cut):
    good = pcd_files(shared_data)[0].read_bytes()
    path = fuzz_dir / "cut.pcd"
    path.write_bytes(good[:cut])
    if cut < PCD_HEADER_BYTES + PCD_POINTS * PCD_ROW_BYTES:
        raises_naming(path, nu.read_radar_pcd)
    else:  # only padding is lost
        assert len(nu.read_radar_pcd(path)) == PCD_POINTS


@FUZZ
@given(data=st.binary(max_size=2000))
def test_pcd_random_bytes_raise_valueerror(fuzz_dir, data):
    path = fuzz_dir / "random.pcd"
    path.write_bytes(data)
    raises_naming(path, nu.read_radar_pcd)


@FUZZ
@given(pos=st.integers(0, PCD_HEADER_BYTES - 1), byte=st.integers(0, 255))
def test_pcd_header_corruption_never_escapes_as_other_errors(shared_data, fuzz_dir, pos, byte):
    good = bytearray(pcd_files(shared_data)[0].read_bytes())
    good[pos] = byte
    path = fuzz_dir / "flip.pcd"
    path.write_bytes(bytes(good))
    pcd = read_or_valueerror(nu.read_radar_pcd, path)
    assert pcd is None or len(pcd) <= len(good) // PCD_ROW_BYTES


# --------------------------------------------------------------------------- rotations


def test_quaternions_and_poses():
    np.testing.assert_allclose(nu.quaternion_to_matrix(Q_YAW90), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(nu.quaternion_to_matrix((2, 0, 0, 0)), np.eye(3))  # normalised
    rng = np.random.default_rng(0)
    for q in rng.normal(size=(20, 4)):
        r = nu.quaternion_to_matrix(q)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        assert np.isclose(np.linalg.det(r), 1)
    yaw = 2.0
    assert np.isclose(nu.matrix_yaw(nu.quaternion_to_matrix((np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)))), yaw)
    q = rng.normal(size=4)
    m = nu.pose_matrix((1, 2, 3), q)
    np.testing.assert_allclose(nu.pose_matrix((1, 2, 3), q, inverse=True) @ m, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], (1, 2, 3))


# --------------------------------------------------------------------------- nuScenes tables


@pytest.fixture
def tiny_nuscenes(tmp_path):
    return build_tiny_nuscenes(tmp_path / "nuscenes")


def test_nuscenes_frame_single_sweep(tiny_nuscenes):
    tables = nu.NuScenesTables(tiny_nuscenes)
    assert nu.list_samples(tables) == ["s0", "s1", "s2"]
    frame = nu.read_nuscenes_frame(tables, "s1")
    assert frame.point_features == nu.NUSCENES_FEATURES and frame.source == "nuscenes"
    # front: sensor (2,0,0) -> ego: R90 (2,0) + (1,0,0.5) = (1,2,0.5); v (1,0) -> (0,1); invalid point filtered.
    # back: R180 (3,1) + (-1,0,0) = (-4,-1,0); v (0.5,0) -> (-0.5,0); dt = 1.5 - 1.52 s.
    expected = [[1, 2, 0.5, 5, 0, 1, 0], [-4, -1, 0, 8, -0.5, 0, -0.02]]
    np.testing.assert_allclose(frame.points, expected, atol=1e-6)
    assert frame.meta["points_per_channel"] == {"RADAR_FRONT": 1, "RADAR_BACK_LEFT": 1}
    assert frame.meta["ref_channel"] == "LIDAR_TOP" and frame.meta["dropped_nonfinite"] == 0


def test_nuscenes_multisweep_moves_past_points_into_current_ego_frame(tiny_nuscenes):
    frame = nu.read_nuscenes_frame(tiny_nuscenes, "s1", nsweeps=3)  # back channel has no earlier sweep
    # earlier front sweep, ego at (9,20): ego (1,2,0.5) -> global (7,21,0.5) -> reference ego (1,3,0.5), dt 0.05 s
    np.testing.assert_allclose(frame.points[1], [1, 3, 0.5, 6, 0, 1, 0.05], atol=1e-6)
    assert len(frame.points) == 3 and frame.meta["dropped_nonfinite"] == 1


def test_nuscenes_boxes_in_ego_frame(tiny_nuscenes):
    boxes = nu.read_nuscenes_frame(tiny_nuscenes, "s1").boxes
    assert list(boxes.names) == ["car", "pedestrian"]
    # car: global (12,25,1) yaw 180 -> ego R(-90) (2,5,1) = (5,-2,1), yaw 90; v = (13-11)/1 s = (2,0) -> (0,-2)
    np.testing.assert_allclose(boxes.center, [[5, -2, 1], [1, 0, 0.9]], atol=1e-6)
    np.testing.assert_allclose(boxes.yaw, [np.pi / 2, -np.pi / 2], atol=1e-6)
    np.testing.assert_allclose(boxes.size, [[2, 4.5, 1.5], [0.6, 0.7, 1.8]])
    np.testing.assert_allclose(boxes.velocity, [[0, -2], [0, 0]], atol=1e-6)
    meta = nu.read_nuscenes_frame(tiny_nuscenes, "s1", classes=("car",)).meta
    assert meta["dropped_annotations"] == 2 and list(meta["velocity_known"]) == [True]


def test_nuscenes_edge_annotations_and_fallbacks(tiny_nuscenes):
    tables = nu.NuScenesTables(tiny_nuscenes)
    np.testing.assert_allclose(nu.annotation_velocity(tables, tables.get("sample_annotation", "a2")), [2, 0, 0])
    assert np.isnan(nu.annotation_velocity(tables, tables.get("sample_annotation", "p1"))).all()
    (tiny_nuscenes / "v1.0-mini" / "sensor.json").unlink()  # channels then come from file names
    frame = nu.read_nuscenes_frame(tiny_nuscenes, "s1", ref_channel="LIDAR_TOP")
    assert frame.meta["ref_channel"] == "RADAR_FRONT"  # the lidar file name carries no channel
    assert frame.meta["points_per_channel"] == {"RADAR_FRONT": 1, "RADAR_BACK_LEFT": 1}
    nu.write_radar_pcd(tiny_nuscenes / "samples/RADAR_BACK_LEFT/n0__RADAR_BACK_LEFT__1520000.pcd",
                       radar_rows((np.inf, 1, 8, 0.5, 0, 0)))
    assert nu.read_nuscenes_frame(tiny_nuscenes, "s1").meta["dropped_nonfinite"] == 1


# --------------------------------------------------------------------------- VoD / TJ4DRadSet: real samples


def vod_root(shared_data) -> Path:
    return shared_data / "vod" / "example_set"


def tj4d_root(shared_data) -> Path:
    return shared_data / "tj4dradset" / "Sample"


def test_vod_boxes_with_radar_points_match_provenance(shared_data):
    root = vod_root(shared_data)
    assert kitti.list_frames(root) == ["00549", "01047", "01201"]
    counts = []
    for frame_id, n_points in zip(kitti.list_frames(root), (322, 352, 242)):
        frame = kitti.read_vod_frame(root, frame_id)
        assert frame.points.shape == (n_points, 7) and frame.point_features == kitti.VOD_FEATURES
        assert frame.meta["upright_frame"] == "lidar" and frame.meta["dropped_nonfinite"] == 0
        has = kitti.boxes_with_points(frame)  # 0.2 m xy / 0.5 m z per side, all labelled objects
        counts.append(f"{has.sum()}/{len(has)}")
    assert counts == ["15/15", "17/24", "18/23"]


def test_vod_class_names_lowercase(shared_data):
    names = set(kitti.read_vod_frame(vod_root(shared_data), "01047").boxes.names)
    assert names == {"car", "cyclist", "pedestrian", "bicycle", "bicycle_rack", "moped_scooter", "rider"}


def test_tj4d_boxes_with_radar_points_match_provenance(shared_data):
    root = tj4d_root(shared_data)
    frames = kitti.list_frames(root)
    assert len(frames) == 41 and frames[0] == "070070"
    hit = total = 0
    for frame_id in frames:
        frame = kitti.read_tj4d_frame(root, frame_id)
        has = kitti.boxes_with_points(frame)
        hit, total = hit + has.sum(), total + len(has)
        assert set(frame.boxes.names) <= {"car"}
    assert (hit, total) == (123, 152)
    first = kitti.read_tj4d_frame(root, "070070")
    xyz = first.points[:, :3].astype(np.float64)
    np.testing.assert_allclose(first.column("range"), np.linalg.norm(xyz, axis=1), atol=1e-4)  # column order


def test_load_frames_native_keeps_tj4d_columns(shared_data):
    from dsfec_jax.data.points.sources import DSFEC_FEATURES, load_frames

    data = f"tj4d:{tj4d_root(shared_data)}"
    native, mapped = load_frames(data, "all", 2, features="native"), load_frames(data, "all", 2)
    assert len(native) == len(mapped) == 2
    for a, b in zip(native, mapped):
        assert a.point_features == kitti.TJ4D_FEATURES and a.points.shape[1] == 8
        assert b.point_features == DSFEC_FEATURES and len(a.points) == len(b.points)
        assert np.array_equal(a.points[:, :3], b.points[:, :3]) and np.array_equal(a.boxes.names, b.boxes.names)
    raw = kitti.read_tj4d_frame(tj4d_root(shared_data), kitti.list_frames(tj4d_root(shared_data))[0])
    assert np.array_equal(native[0].points, raw.points)  # untouched, only the classes are mapped


def test_load_frames_native_vod_maps_classes_and_drops_the_rest(shared_data):
    from dsfec_jax.data.points.sources import load_frames

    frame = load_frames(f"vod:{vod_root(shared_data)}", "all", 3, features="native")[1]  # 01047
    raw = kitti.read_vod_frame(vod_root(shared_data), "01047")
    assert frame.point_features == kitti.VOD_FEATURES and np.array_equal(frame.points, raw.points)
    assert set(frame.boxes.names) == {"car", "pedestrian", "bicycle"}  # cyclist -> bicycle
    kept = np.isin(raw.boxes.names, ["car", "pedestrian", "cyclist"])
    assert len(frame.boxes) == kept.sum()  # parked bicycles, rider, bicycle_rack, moped_scooter dropped
    assert (frame.boxes.names == "bicycle").sum() == (raw.boxes.names == "cyclist").sum() == 4
    # the label rows (2D boxes for VoD's 40 px rule) stay aligned with the kept boxes
    np.testing.assert_array_equal(frame.meta["kitti_labels"].bbox, raw.meta["kitti_labels"].bbox[kept])
    assert frame.meta["image_size"] == kitti.VOD_IMAGE_SIZE == (1936, 1216)


def test_class_maps_per_source_keep_the_canonical_bicycle():
    """The VRU class is "bicycle" (ridden) in the synthetic and nuScenes sources; in VoD a 'bicycle'
    has no rider (parked) and, as in VoD's evaluation, is no class, while its 'cyclist' is ours."""
    from dsfec_jax.data.points.frame import Boxes, Frame
    from dsfec_jax.data.points.sources import canonical_classes, to_dsfec_frame

    names = np.array(["bicycle", "cyclist", "rider", "pedestrian"])
    boxes = Boxes(np.arange(12, dtype=np.float32).reshape(4, 3), np.ones((4, 3), np.float32), np.zeros(4, np.float32),
                  np.zeros((4, 2), np.float32), names)
    points = np.zeros((1, 7), np.float32)

    def mapped(source, fn=canonical_classes):
        return list(fn(Frame(points, kitti.VOD_FEATURES, boxes, source=source)).boxes.names)

    assert mapped("vod") == mapped("tj4d") == ["bicycle", "pedestrian"]  # the cyclist's box
    assert mapped("synthetic") == mapped("nuscenes") == ["bicycle", "pedestrian"]  # the bicycle's box
    vod = canonical_classes(Frame(points, kitti.VOD_FEATURES, boxes, source="vod"))
    np.testing.assert_array_equal(vod.boxes.center, boxes.center[[1, 3]])
    assert mapped("synthetic", to_dsfec_frame) == ["bicycle", "pedestrian"]  # synthetic4d with DSFEC columns


def test_load_frames_synthetic4d_and_errors():
    from dsfec_jax.data.points.sources import DSFEC_FEATURES, load_frames

    frames = load_frames("synthetic4d", "train", 2, features="native")
    assert len(frames) == 2 and frames[1].point_features == kitti.VOD_FEATURES
    mapped = load_frames("synthetic4d", "train", 2)  # features="dsfec": the DSFEC models' columns
    assert mapped[1].point_features == DSFEC_FEATURES and len(mapped[1].points) == len(frames[1].points)
    assert set(frames[0].boxes.names) <= {"car", "truck", "pedestrian", "bicycle"}
    with pytest.raises(ValueError, match=r"features='raw'.*dsfec.*native"):
        load_frames("synthetic", "train", 1, features="raw")
    with pytest.raises(ValueError, match=r"'radar:x'.*synthetic4d.*tj4d:PATH"):
        load_frames("radar:x", "train", 1)
    with pytest.raises(ValueError, match=r"synthetic4d.*'all'"):
        load_frames("synthetic4d", "all", 1)


def test_box_conventions_agree_where_frames_align(shared_data):
    """Camera-upright and LiDAR-upright conversions differ only by the calibrations' small tilt."""
    root = vod_root(shared_data)
    frame = kitti.read_vod_frame(root, "00549")
    cam = kitti.kitti_to_boxes(frame.meta["kitti_labels"], frame.meta["calib"].sensor_from_cam())
    assert np.abs(cam.center - frame.boxes.center).max() < 0.15
    dyaw = np.angle(np.exp(1j * (cam.yaw - frame.boxes.yaw)))
    assert np.abs(dyaw).max() < np.radians(1)
    # the common -ry - pi/2 shortcut is within the radar/camera yaw offset (< 1 deg here)
    shortcut = -frame.meta["kitti_labels"].rotation_y - np.pi / 2
    assert np.abs(np.angle(np.exp(1j * (shortcut - frame.boxes.yaw)))).max() < np.radians(1)


# --------------------------------------------------------------------------- KITTI: synthetic geometry


def level_calib(tmp_path, translation=(0.1, 1.2, -0.3), name="calib.txt") -> Path:
    """Radar x fwd / y left / z up vs camera x right / y down / z fwd, as KITTI's velodyne."""
    tr = np.array([[0, -1, 0, translation[0]], [0, 0, -1, translation[1]], [1, 0, 0, translation[2]]], float)
    text = (f"P2: {' '.join(['1'] * 12)}\nR0_rect: 1 0 0 0 1 0 0 0 1\n"
            f"Tr_velo_to_cam: {' '.join(map(str, tr.ravel()))}\nTr_imu_to_velo:\n")
    path = tmp_path / name
    path.write_text(text)
    return path


def test_kitti_label_to_radar_box_by_hand(tmp_path):
    calib = kitti.read_calib(level_calib(tmp_path))
    label = tmp_path / "label.txt"
    label.write_text("Car 0 0 0 0 0 10 10 1.5 1.8 4.2 2.0 1.6 20.0 0.3\n"
                     "DontCare -1 -1 -10 0 0 5 5 -1 -1 -1 -1000 -1000 -1000 -10\n")
    labels = kitti.read_kitti_labels(label)
    assert list(labels.names) == ["Car", "DontCare"]
    boxes = kitti.kitti_to_boxes(labels.select(np.array([True, False])), calib.sensor_from_cam())
    # camera bottom centre (2, 1.6, 20) -> radar (20 - (-0.3), -(2 - 0.1), -(1.6 - 1.2)) = (20.3, -1.9, -0.4); + h/2
    np.testing.assert_allclose(boxes.center, [[20.3, -1.9, -0.4 + 0.75]], atol=1e-5)
    np.testing.assert_allclose(boxes.size, [[1.8, 4.2, 1.5]])
    np.testing.assert_allclose(boxes.yaw, [-0.3 - np.pi / 2], atol=1e-6)
    assert list(boxes.names) == ["car"]


@pytest.mark.parametrize("ry", [-3.0, -1.2, 0.0, 0.4, 2.5])
def test_points_inside_camera_box_are_inside_radar_box(shared_data, ry):
    """Sample the inner part of a camera-frame box, map to radar with a real (tilted) calibration."""
    calib = kitti.read_calib(tj4d_root(shared_data) / "training" / "calib" / "070070.txt")
    h, w, l, loc = 1.6, 1.9, 4.5, np.array([3.0, 1.5, 25.0])
    labels = kitti.KittiLabels(np.array(["Car"]), *np.zeros((3, 1)), np.zeros((1, 4)), np.array([[h, w, l]]),
                               loc[None], np.array([ry]), np.ones(1))
    boxes = kitti.kitti_to_boxes(labels, calib.sensor_from_cam())
    rng = np.random.default_rng(1)
    u = rng.uniform(-0.4, 0.4, (200, 3))  # fractions of the box extent, inner 80 %
    local = np.stack([u[:, 0] * l, -h / 2 + u[:, 1] * h, u[:, 2] * w], 1)  # along, down, across
    rot = np.array([[np.cos(ry), 0, np.sin(ry)], [0, 1, 0], [-np.sin(ry), 0, np.cos(ry)]])
    cam_pts = local @ rot.T + loc
    radar_pts = cam_pts @ calib.sensor_from_cam()[:3, :3].T + calib.sensor_from_cam()[:3, 3]
    assert points_in_boxes(radar_pts, boxes.center, boxes.size, boxes.yaw).all()
    outside = radar_pts + np.array([0, 0, h])  # lifted by a box height: above it
    assert not points_in_boxes(outside, boxes.center, boxes.size, boxes.yaw).any()


def test_box_point_counts_margins():
    pts = np.array([[0, 0, 0], [2.1, 0, 0], [0, 0, 1.4]], float)
    c, s, y = np.zeros((1, 3)), np.array([[1.0, 4.0, 2.0]]), np.zeros(1)
    assert box_point_counts(pts, c, s, y).tolist() == [1]
    assert box_point_counts(pts, c, s, y, margin_xy=0.2, margin_z=0.5).tolist() == [3]
    assert box_point_counts(np.zeros((0, 3)), c, s, y).tolist() == [0]


def test_dontcare_dropped_and_counted(shared_data, tmp_path):
    root = tmp_path / "tj"
    for sub in ("velodyne", "calib", "label_2"):
        (root / "training" / sub).mkdir(parents=True)
    np.zeros((3, 8), np.float32).tofile(root / "training/velodyne/000001.bin")
    (root / "training/calib/000001.txt").write_text(level_calib(tmp_path).read_text())
    (root / "training/label_2/000001.txt").write_text(
        "Truck 0 0 0 0 0 1 1 3 2.5 9 0 1.5 30 0\nDontCare -1 -1 -10 0 0 1 1 -1 -1 -1 -1000 -1000 -1000 -10\n")
    frame = kitti.read_tj4d_frame(root, "000001")
    assert list(frame.boxes.names) == ["truck"] and frame.meta["dropped_dontcare"] == 1
    assert kitti.list_frames(root) == ["000001"]


# --------------------------------------------------------------------------- KITTI: errors and fuzzing


def test_kitti_errors_name_the_file(tmp_path):
    path = tmp_path / "scan.bin"
    path.write_bytes(np.zeros(15, np.float32).tobytes())
    assert "multiple of 28" in raises_naming(path, kitti.read_radar_bin, 7)
    assert "multiple of 32" in raises_naming(path, kitti.read_radar_bin, 8)
    label = tmp_path / "label.txt"
    for bad in ("Car 0 0 0 1 2 3 4 1.5 1.8 4.2 2.0 1.6 20.0\n", "Car 0 0 0 1 2 3 4 1.5 x 4.2 2.0 1.6 20.0 0.3\n",
                "Car 0 0 0 1 2 3 4 1.5 -1.8 4.2 2.0 1.6 20.0 0.3\n", "Car 0 0 0 1 2 3 4 1.5 nan 4.2 2 1.6 20 0.3\n"):
        label.write_text(bad)
        assert "line 1" in raises_naming(label, kitti.read_kitti_labels)
    calib = level_calib(tmp_path)
    text = calib.read_text()
    calib.write_text(text.replace("R0_rect", "R1_rect"))
    assert "R0_rect" in raises_naming(calib, kitti.read_calib)
    calib.write_text(text.replace("Tr_velo_to_cam: 0.0 ", "Tr_velo_to_cam: "))
    assert "expected 12" in raises_naming(calib, kitti.read_calib)
    calib.write_bytes(b"\xff\xfe" + text.encode())
    assert "UTF-8" in raises_naming(calib, kitti.read_calib)


@FUZZ
@given(data=st.binary(max_size=400), width=st.sampled_from([7, 8]))
def test_bin_fuzz(fuzz_dir, data, width):
    path = fuzz_dir / "fuzz.bin"
    path.write_bytes(data)
    if len(data) % (4 * width):
        raises_naming(path, kitti.read_radar_bin, width)
    else:
        points, dropped = kitti.read_radar_bin(path, width)
        assert points.shape[1] == width and len(points) + dropped == len(data) // (4 * width)
        assert np.isfinite(points).all()


@FUZZ
@given(data=st.one_of(st.binary(max_size=300), st.text(alphabet=" \n:.-eE0123456789CarP2R0_rectTr", max_size=300)))
def test_label_and_calib_random_content(fuzz_dir, data):
    for name, fn in (("fuzz_label.txt", kitti.read_kitti_labels), ("fuzz_calib.txt", kitti.read_calib)):
        path = fuzz_dir / name
        path.write_bytes(data if isinstance(data, bytes) else data.encode())
        read_or_valueerror(fn, path)


@FUZZ
@given(cut=st.floats(0, 1))
def test_label_and_calib_truncations(shared_data, fuzz_dir, cut):
    sources = [(vod_root(shared_data) / "lidar/training/label_2/01047.txt", kitti.read_kitti_labels),
               (tj4d_root(shared_data) / "training/label_2/070070.txt", kitti.read_kitti_labels),
               (vod_root(shared_data) / "radar/training/calib/00549.txt", kitti.read_calib),
               (tj4d_root(shared_data) / "training/calib/070070.txt", kitti.read_calib)]
    for source, fn in sources:
        text = source.read_text()
        n = int(cut * len(text))
        path = fuzz_dir / f"cut_{source.parent.name}{source.suffix}"
        path.write_text(text[:n])
        result = read_or_valueerror(fn, path)
        if fn is kitti.read_kitti_labels and result is not None:  # cut at a line or score-column end
            assert len(result) <= len(fn(source))
        if fn is kitti.read_calib and n < text.index("Tr_velo_to_cam") + len("Tr_velo_to_cam: "):
            assert result is None  # a required key is missing or empty

"""KITTI-layout 4D-radar readers: View-of-Delft (VoD) and TJ4DRadSet, into the one `Frame` schema.

Both datasets store radar scans where KITTI stores LiDAR (`velodyne/<id>.bin`, float32 rows),
calibration as KITTI text (`Tr_velo_to_cam` maps the *radar* frame to the camera frame) and
labels as KITTI text in the rectified camera frame (location = bottom centre of the box).

    VoD   .bin: N x 7 = x y z RCS v_r v_r_compensated time      (root/radar/training/...)
    TJ4D  .bin: N x 8 = x y z V_r Range Power Alpha Beta          (root/training/...)

Boxes are returned in the radar frame with the project conventions (centre z at the box centre,
size (w, l, h), yaw about +z from +x). Which axis a label box is upright about differs:
VoD annotates in the LiDAR frame (rotation about the LiDAR's -Z, docs/ANNOTATION.md; its devkit
rebuilds boxes upright in the LiDAR frame with yaw = -(ry + pi/2)), while TJ4DRadSet's own
viewer builds them upright in the camera frame (rotation about camera +y). The camera is tilted
by a few degrees against both radars, so the choice moves box centres by up to ~0.1 m.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from dsfec_jax.boxes.geometry import box_point_counts
from dsfec_jax.core.columns import TJ4D_FEATURES, VOD_FEATURES
from dsfec_jax.data.points.frame import Boxes, Frame

CALIB_SHAPES = {"P2": (3, 4), "R0_rect": (3, 3), "Tr_velo_to_cam": (3, 4)}
IGNORED_CLASSES = ("dontcare",)
# VoD's camera image, 1936 x 1216 pixels (VoD's README; the example_set JPEGs): what its 2D boxes are clipped to.
VOD_IMAGE_SIZE = (1936, 1216)
# VoD's radar -> camera extrinsic: Tr_velo_to_cam of radar/training/calib in VoD's public example_set (the
# same in its three frames; R0_rect is the identity there). The nominal calibration for frames that carry
# none, i.e. the VoD-like synthetic 4D benchmark: the camera sits ~1.4 m behind and ~1 m above the radar.
VOD_RADAR_TO_CAMERA = np.array([[-0.013857, -0.9997468, 0.01772762, 0.05283124],
                                [0.10934269, -0.01913807, -0.99381983, 0.98100483],
                                [0.99390751, -0.01183297, 0.1095802, 1.44445002]])


def _fail(path, what: str) -> ValueError:
    return ValueError(f"{path}: {what}")


def _read_text(path) -> str:
    try:
        return Path(path).read_bytes().decode("utf-8")
    except UnicodeDecodeError as e:  # a binary file in a text slot: say which file
        raise _fail(path, f"not UTF-8 text ({e.reason} at byte {e.start})") from None


def _floats(path, tokens, what: str) -> np.ndarray:
    try:
        values = np.array([float(t) for t in tokens], np.float64)
    except ValueError:
        raise _fail(path, f"{what}: expected numbers, got {' '.join(tokens)[:80]!r}") from None
    if not np.all(np.isfinite(values)):
        raise _fail(path, f"{what}: expected finite numbers, got {' '.join(tokens)[:80]!r}")
    return values


# --------------------------------------------------------------------------- radar scans


def read_radar_bin(path, num_features: int) -> tuple[np.ndarray, int]:
    """(N, num_features) float32 rows of a KITTI-style .bin, and how many non-finite rows were dropped."""
    raw = Path(path).read_bytes()
    row = 4 * num_features
    if len(raw) % row:
        raise _fail(path, f"size {len(raw)} B is not a multiple of {row} B "
                          f"({num_features} float32 per point)")
    points = np.frombuffer(raw, "<f4").reshape(-1, num_features).astype(np.float32)
    finite = np.all(np.isfinite(points), axis=1)
    return points[finite], int((~finite).sum())


# --------------------------------------------------------------------------- calibration


@dataclasses.dataclass(frozen=True)
class KittiCalib:
    """KITTI calibration; in VoD and TJ4DRadSet the 'velo' sensor of Tr_velo_to_cam is the radar."""
    P2: np.ndarray              # (3, 4) camera projection
    R0_rect: np.ndarray         # (3, 3) rectifying rotation
    Tr_velo_to_cam: np.ndarray  # (3, 4) sensor (radar here) -> camera
    path: str = ""

    def cam_from_sensor(self) -> np.ndarray:
        """(4, 4) sensor -> rectified camera, as KITTI composes it: R0_rect @ Tr_velo_to_cam."""
        return _homogeneous(self.R0_rect) @ _homogeneous(self.Tr_velo_to_cam)

    def sensor_from_cam(self) -> np.ndarray:
        """(4, 4) rectified camera -> sensor; calibrations are not exactly rigid, so invert fully."""
        return np.linalg.inv(self.cam_from_sensor())


def _homogeneous(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[: m.shape[0], : m.shape[1]] = m
    return out


def read_calib(path) -> KittiCalib:
    """Parse a KITTI calib file; P2, R0_rect and Tr_velo_to_cam must be present and well formed."""
    entries = {}
    for n, line in enumerate(_read_text(path).splitlines(), 1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        if not sep:
            raise _fail(path, f"line {n}: expected 'key: values', got {line[:80]!r}")
        entries[key.strip()] = values.split()
    mats = {}
    for key, shape in CALIB_SHAPES.items():
        if key not in entries:
            raise _fail(path, f"missing calibration key {key!r} (expected {', '.join(CALIB_SHAPES)})")
        values = _floats(path, entries[key], key)
        if values.size != math.prod(shape):
            raise _fail(path, f"{key} has {values.size} values; expected {math.prod(shape)}")
        mats[key] = values.reshape(shape)
    calib = KittiCalib(**mats, path=str(path))
    if abs(np.linalg.det(calib.cam_from_sensor())) < 1e-6:  # inverting it is how boxes reach the radar
        raise _fail(path, "R0_rect @ Tr_velo_to_cam is singular; expected a rigid transform")
    return calib


# --------------------------------------------------------------------------- labels


@dataclasses.dataclass(frozen=True)
class KittiLabels:
    """KITTI label columns, one row per object (camera frame, location = bottom centre)."""
    names: np.ndarray      # (M,) str, as written in the file
    truncated: np.ndarray  # (M,)
    occluded: np.ndarray   # (M,)
    alpha: np.ndarray      # (M,)
    bbox: np.ndarray       # (M, 4) left, top, right, bottom in pixels
    hwl: np.ndarray        # (M, 3) height, width, length
    location: np.ndarray   # (M, 3) x, y, z in the rectified camera frame
    rotation_y: np.ndarray  # (M,) about the camera's +y (down) axis
    score: np.ndarray      # (M,) 16th column where present, else 1

    def __len__(self) -> int:
        return len(self.names)

    def select(self, keep) -> "KittiLabels":
        return KittiLabels(**{f.name: getattr(self, f.name)[keep] for f in dataclasses.fields(self)})


def _parse_label_line(path, n: int, line: str) -> tuple[str, np.ndarray]:
    tokens = line.split()
    if len(tokens) not in (15, 16):
        raise _fail(path, f"line {n}: {len(tokens)} columns; expected 15 (KITTI) or 16 (with score)")
    values = _floats(path, tokens[1:], f"line {n}")
    if tokens[0].lower() not in IGNORED_CLASSES and not np.all(values[7:10] > 0):
        raise _fail(path, f"line {n}: dimensions h w l = {values[7:10].tolist()}; expected > 0")
    return tokens[0], np.append(values, 1.0) if len(tokens) == 15 else values


def read_kitti_labels(path) -> KittiLabels:
    """Parse a KITTI label file (15 columns, or 16 with a trailing score as VoD writes)."""
    rows = [_parse_label_line(path, n, line)
            for n, line in enumerate(_read_text(path).splitlines(), 1) if line.strip()]
    v = np.array([r[1] for r in rows], np.float64).reshape(-1, 15)
    names = np.array([r[0] for r in rows], dtype=str).reshape(-1)
    return KittiLabels(names, v[:, 0], v[:, 1], v[:, 2], v[:, 3:7], v[:, 7:10], v[:, 10:13], v[:, 13], v[:, 14])


def kitti_to_boxes(labels: KittiLabels, sensor_from_cam: np.ndarray,
                   upright_from_cam: np.ndarray | None = None) -> Boxes:
    """Label boxes into a sensor frame: centre at mid-height, size (w, l, h), yaw about +z.

    upright_from_cam: the z-up frame the boxes were annotated upright in (VoD: its LiDAR), where
    the heading is yaw = -(ry + pi/2). None: upright in the camera frame (KITTI's own definition:
    box up = camera -y, heading = (cos ry, 0, -sin ry)). Either way the true box centre and
    heading vector are mapped into the sensor frame and the heading is projected onto its x-y plane.
    """
    h, w, l = labels.hwl.T
    if upright_from_cam is None:
        centre = labels.location - np.stack([0 * h, h / 2, 0 * h], 1)  # camera y points down
        heading = np.stack([np.cos(labels.rotation_y), 0 * h, -np.sin(labels.rotation_y)], 1)
        sensor_from_frame = sensor_from_cam
    else:
        centre = _apply(upright_from_cam, labels.location) + np.stack([0 * h, 0 * h, h / 2], 1)
        yaw_u = -(labels.rotation_y + np.pi / 2)
        heading = np.stack([np.cos(yaw_u), np.sin(yaw_u), 0 * h], 1)
        sensor_from_frame = sensor_from_cam @ np.linalg.inv(upright_from_cam)
    heading = heading @ sensor_from_frame[:3, :3].T
    yaw = np.arctan2(heading[:, 1], heading[:, 0])
    f32 = np.float32
    return Boxes(_apply(sensor_from_frame, centre).astype(f32), np.stack([w, l, h], 1).astype(f32),
                 yaw.astype(f32), np.zeros((len(labels), 2), f32),
                 np.array([n.lower() for n in labels.names], dtype="<U32").reshape(-1))


def _apply(transform: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    return xyz @ transform[:3, :3].T + transform[:3, 3]


# --------------------------------------------------------------------------- frames


def list_frames(root, split: str = "training", radar_dir: str = "radar") -> list[str]:
    """Frame ids (file stems) of a VoD root (`root/<radar_dir>/<split>`) or TJ4D root (`root/<split>`)."""
    for base in (Path(root) / radar_dir / split, Path(root) / split, Path(root)):
        if (base / "velodyne").is_dir():
            return sorted(p.stem for p in (base / "velodyne").glob("*.bin"))
    raise FileNotFoundError(f"no velodyne/ folder under {root} (looked in {radar_dir}/{split}/, {split}/, ./)")


def _frame(frame_id: str, source: str, points: np.ndarray, features: tuple[str, ...], dropped: int,
           calib: KittiCalib, labels: KittiLabels, label_path: Path, upright_from_cam: np.ndarray | None,
           **extra_meta) -> Frame:
    ignored = np.isin(np.char.lower(labels.names.astype(str)), IGNORED_CLASSES)
    kept = labels.select(~ignored)
    boxes = kitti_to_boxes(kept, calib.sensor_from_cam(), upright_from_cam)
    meta = {"dropped_nonfinite": dropped, "dropped_dontcare": int(ignored.sum()), "calib": calib,
            "kitti_labels": kept, "label_path": str(label_path),
            "upright_frame": "camera" if upright_from_cam is None else "lidar", **extra_meta}
    return Frame(points, features, boxes, frame_id=str(frame_id), source=source, meta=meta)


def read_vod_frame(root, frame_id, split: str = "training", radar_dir: str = "radar") -> Frame:
    """One View-of-Delft radar frame; root holds radar/ (or radar_3frames/, radar_5frames/) and lidar/.

    Labels come from <radar_dir>/<split>/label_2/<id>.txt, or lidar/<split>/label_2/ where the radar
    folder holds VoD's raw JSON instead (the public example_set). Boxes are upright in the LiDAR frame
    when lidar/<split>/calib/<id>.txt exists (VoD's definition), else in the camera frame.
    meta["kitti_labels"] keeps the label rows (their 2D boxes) aligned with the boxes; meta["image_size"]
    is VoD's camera image size.
    """
    root, frame_id = Path(root), str(frame_id)
    radar = root / radar_dir / split
    points, dropped = read_radar_bin(radar / "velodyne" / f"{frame_id}.bin", len(VOD_FEATURES))
    calib = read_calib(radar / "calib" / f"{frame_id}.txt")
    label_path = radar / "label_2" / f"{frame_id}.txt"
    if not label_path.exists():
        label_path = root / "lidar" / split / "label_2" / f"{frame_id}.txt"
    lidar_calib_path = root / "lidar" / split / "calib" / f"{frame_id}.txt"
    upright = read_calib(lidar_calib_path).sensor_from_cam() if lidar_calib_path.exists() else None
    return _frame(frame_id, "vod", points, VOD_FEATURES, dropped, calib, read_kitti_labels(label_path),
                  label_path, upright, image_size=VOD_IMAGE_SIZE)


def read_tj4d_frame(root, frame_id, split: str = "training") -> Frame:
    """One TJ4DRadSet frame from root/<split>/{velodyne,calib,label_2}; boxes upright in the camera frame."""
    base = Path(root) / split if (Path(root) / split).is_dir() else Path(root)
    frame_id = str(frame_id)
    points, dropped = read_radar_bin(base / "velodyne" / f"{frame_id}.bin", len(TJ4D_FEATURES))
    label_path = base / "label_2" / f"{frame_id}.txt"
    return _frame(frame_id, "tj4d", points, TJ4D_FEATURES, dropped, read_calib(base / "calib" / f"{frame_id}.txt"),
                  read_kitti_labels(label_path), label_path, None)


def boxes_with_points(frame: Frame, margin_xy: float = 0.2, margin_z: float = 0.5) -> np.ndarray:
    """(M,) bool: box m holds >= 1 radar point, with the per-side margins the data PROVENANCE counts use."""
    b = frame.boxes
    return box_point_counts(frame.points[:, :3], b.center, b.size, b.yaw, margin_xy, margin_z) > 0


__all__ = ["VOD_FEATURES", "TJ4D_FEATURES", "VOD_IMAGE_SIZE", "VOD_RADAR_TO_CAMERA", "KittiCalib", "KittiLabels",
           "read_radar_bin", "read_calib",
           "read_kitti_labels", "kitti_to_boxes", "list_frames", "read_vod_frame", "read_tj4d_frame",
           "boxes_with_points"]

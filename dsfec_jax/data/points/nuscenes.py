"""nuScenes radar: binary PCD reader/writer, devkit-style point filters, and JSON-table frames.

Radar sweeps are binary PCD v0.7 files with 18 fields from the Continental ARS408 (see
RADAR_FIELDS). Real files are zero-padded after the points (fixed size), so exactly
WIDTH x HEIGHT rows are read and trailing bytes are ignored, as the nuScenes devkit does.

`read_nuscenes_frame` builds one `Frame` for a sample from a dataroot holding `v1.0-*/` JSON
tables: points of the 5 radar channels (optionally several sweeps each, following `prev` links)
moved into the ego frame of a reference channel's key frame, and annotations moved from the
global frame into that same ego frame. Quaternions are (w, x, y, z), as nuScenes stores them.
The tables, with their field checks and path rule, are `nuscenes_tables.NuScenesTables`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from dsfec_jax.core.columns import NUSCENES_FEATURES
from dsfec_jax.data.points.frame import Boxes, Frame
from dsfec_jax.data.points.nuscenes_tables import NuScenesTables, list_samples

RADAR_FIELDS = ("x", "y", "z", "dyn_prop", "id", "rcs", "vx", "vy", "vx_comp", "vy_comp", "is_quality_valid",
                "ambig_state", "x_rms", "y_rms", "invalid_state", "pdh0", "vx_rms", "vy_rms")
RADAR_SIZES = (4, 4, 4, 1, 2, 4, 4, 4, 4, 4, 1, 1, 1, 1, 1, 1, 1, 1)
RADAR_TYPES = "FFFIIFFFFFIIIIIIII"
RADAR_CHANNELS = ("RADAR_FRONT", "RADAR_FRONT_LEFT", "RADAR_FRONT_RIGHT", "RADAR_BACK_LEFT", "RADAR_BACK_RIGHT")

# nuscenes-devkit defaults (RadarPointCloud): keep valid, unambiguous points of any dynamic property.
DEFAULT_INVALID_STATES = (0,)
DEFAULT_DYNPROP_STATES = tuple(range(7))
DEFAULT_AMBIG_STATES = (3,)

# nuScenes detection-challenge mapping (devkit eval/detection/utils.py); other categories are dropped.
DETECTION_MAPPING = {
    "movable_object.barrier": "barrier", "vehicle.bicycle": "bicycle", "vehicle.bus.bendy": "bus",
    "vehicle.bus.rigid": "bus", "vehicle.car": "car", "vehicle.construction": "construction_vehicle",
    "vehicle.motorcycle": "motorcycle", "human.pedestrian.adult": "pedestrian",
    "human.pedestrian.child": "pedestrian", "human.pedestrian.construction_worker": "pedestrian",
    "human.pedestrian.police_officer": "pedestrian", "movable_object.trafficcone": "traffic_cone",
    "vehicle.trailer": "trailer", "vehicle.truck": "truck",
}

_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_MAX_HEADER = 4096  # real headers are 370 B; a missing DATA line must not make us scan a whole file


def _fail(path, what: str) -> ValueError:
    return ValueError(f"{path}: {what}")


# --------------------------------------------------------------------------- PCD


def _header_lines(path, raw: bytes) -> tuple[dict[str, list[str]], int]:
    """Header entries keyed by PCD keyword, and the byte offset where the point data starts."""
    entries, offset = {}, 0
    while True:
        end = raw.find(b"\n", offset, _MAX_HEADER)
        if end < 0:
            raise _fail(path, f"PCD header has no 'DATA' line within {_MAX_HEADER} B (truncated or not a PCD)")
        try:
            line = raw[offset:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise _fail(path, f"PCD header byte {offset}: expected ASCII text") from None
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key not in _PCD_KEYS:
            raise _fail(path, f"unknown PCD header keyword {key!r}; expected one of {_PCD_KEYS}")
        entries[key] = values
        if key == "DATA":
            return entries, offset


def _header_int(path, entries, key: str) -> int:
    values = entries.get(key, [])
    if len(values) != 1 or not values[0].isdigit():
        raise _fail(path, f"PCD header {key} = {values}; expected one non-negative integer")
    return int(values[0])


def _pcd_dtype(path, entries) -> np.dtype:
    """Packed little-endian row dtype; only the 18-field nuScenes radar layout is accepted."""
    fields = tuple(entries.get("FIELDS", []))
    if fields != RADAR_FIELDS:
        raise _fail(path, f"PCD has {len(fields)} FIELDS {fields}; expected the {len(RADAR_FIELDS)} "
                          f"nuScenes radar fields {RADAR_FIELDS}")
    expected = {"SIZE": [str(s) for s in RADAR_SIZES], "TYPE": list(RADAR_TYPES), "COUNT": ["1"] * len(RADAR_FIELDS)}
    for key, want in expected.items():
        if entries.get(key) != want:
            raise _fail(path, f"PCD header {key} = {entries.get(key)}; expected {' '.join(want)}")
    kinds = {"F": "f", "I": "i", "U": "u"}
    return np.dtype([(f, f"<{kinds[t]}{s}") for f, s, t in zip(RADAR_FIELDS, RADAR_SIZES, RADAR_TYPES)])


def read_radar_pcd(path) -> np.ndarray:
    """Structured array (one named column per RADAR_FIELDS entry) of a nuScenes radar PCD.

    Raises ValueError naming the file for a corrupt or truncated header or body, non-binary DATA,
    or any field layout other than the 18 nuScenes radar fields.
    """
    raw = Path(path).read_bytes()
    entries, offset = _header_lines(path, raw)
    if entries["DATA"] != ["binary"]:
        raise _fail(path, f"PCD DATA {' '.join(entries['DATA'])!r}; expected 'binary'")
    dtype = _pcd_dtype(path, entries)
    width, height = _header_int(path, entries, "WIDTH"), _header_int(path, entries, "HEIGHT")
    n = width * height
    if "POINTS" in entries and _header_int(path, entries, "POINTS") != n:
        raise _fail(path, f"PCD POINTS {entries['POINTS'][0]} != WIDTH x HEIGHT = {n}")
    if len(raw) - offset < n * dtype.itemsize:
        raise _fail(path, f"PCD body has {len(raw) - offset} B; expected {n} points x {dtype.itemsize} B "
                          f"= {n * dtype.itemsize} B (truncated)")
    return np.frombuffer(raw, dtype, count=n, offset=offset).copy()  # trailing padding ignored


def write_radar_pcd(path, points, pad_to: int = 0) -> None:
    """Write a nuScenes-style radar PCD from a structured array or an (N, 18) numeric array.

    pad_to: zero-pad the file to this many bytes, as real nuScenes sweeps are.
    """
    points = _as_structured(points)
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
              f"FIELDS {' '.join(RADAR_FIELDS)}\nSIZE {' '.join(map(str, RADAR_SIZES))}\n"
              f"TYPE {' '.join(RADAR_TYPES)}\nCOUNT {' '.join(['1'] * len(RADAR_FIELDS))}\n"
              f"WIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\nDATA binary\n")
    body = header.encode("ascii") + points.tobytes()
    Path(path).write_bytes(body + b"\0" * max(0, pad_to - len(body)))


def _as_structured(points) -> np.ndarray:
    dtype = _pcd_dtype("<array>", {"FIELDS": list(RADAR_FIELDS), "SIZE": [str(s) for s in RADAR_SIZES],
                                   "TYPE": list(RADAR_TYPES), "COUNT": ["1"] * len(RADAR_FIELDS)})
    points = np.asarray(points)
    if points.dtype.names is not None:
        return points.astype(dtype)
    if points.ndim != 2 or points.shape[1] != len(RADAR_FIELDS):
        raise ValueError(f"radar points have shape {points.shape}; expected (N, {len(RADAR_FIELDS)})")
    out = np.zeros(len(points), dtype)
    for i, name in enumerate(RADAR_FIELDS):
        out[name] = points[:, i]
    return out


# --------------------------------------------------------------------------- point filters and features


def drop_nonfinite(pcd: np.ndarray) -> tuple[np.ndarray, int]:
    """Drop rows with a NaN/inf float field (the devkit treats a NaN first point as an empty sweep)."""
    floats = [f for f, t in zip(RADAR_FIELDS, RADAR_TYPES) if t == "F"]
    finite = np.all([np.isfinite(pcd[f]) for f in floats], axis=0) if len(pcd) else np.ones(0, bool)
    return pcd[finite], int((~finite).sum())


def filter_radar_points(pcd: np.ndarray, invalid_states: Iterable[int] = DEFAULT_INVALID_STATES,
                        dynprop_states: Iterable[int] = DEFAULT_DYNPROP_STATES,
                        ambig_states: Iterable[int] = DEFAULT_AMBIG_STATES) -> np.ndarray:
    """Keep points whose invalid_state, dyn_prop and ambig_state are in the given sets (devkit semantics)."""
    keep = (np.isin(pcd["invalid_state"], list(invalid_states)) & np.isin(pcd["dyn_prop"], list(dynprop_states))
            & np.isin(pcd["ambig_state"], list(ambig_states)))
    return pcd[keep]


def radar_features(pcd: np.ndarray, transform: np.ndarray | None = None, dt: float = 0.0) -> np.ndarray:
    """(N, 7) float32 NUSCENES_FEATURES; transform (4x4) moves xyz and rotates the compensated velocity."""
    xyz = np.stack([pcd["x"], pcd["y"], pcd["z"]], 1).astype(np.float64)
    vel = np.stack([pcd["vx_comp"], pcd["vy_comp"], np.zeros(len(pcd))], 1).astype(np.float64)
    if transform is not None:
        xyz = xyz @ transform[:3, :3].T + transform[:3, 3]
        vel = vel @ transform[:3, :3].T  # a velocity is a direction: rotate, never translate
    cols = [xyz, pcd["rcs"][:, None], vel[:, :2], np.full((len(pcd), 1), dt)]
    return np.concatenate(cols, 1).astype(np.float32)


# --------------------------------------------------------------------------- rotations


def quaternion_to_matrix(q: Sequence[float]) -> np.ndarray:
    """(3, 3) rotation of a (w, x, y, z) quaternion; normalised first, as stored values drift."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_yaw(rotation: np.ndarray) -> float:
    """Heading of the rotated +x axis in the x-y plane (the devkit's quaternion_yaw)."""
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def pose_matrix(translation: Sequence[float], rotation: Sequence[float], inverse: bool = False) -> np.ndarray:
    """(4, 4) child -> parent transform of a nuScenes pose record (or parent -> child if inverse)."""
    r, t = quaternion_to_matrix(rotation), np.asarray(translation, np.float64)
    m = np.eye(4)
    if inverse:  # rigid inverse: exact, no matrix inversion needed
        m[:3, :3], m[:3, 3] = r.T, -r.T @ t
    else:
        m[:3, :3], m[:3, 3] = r, t
    return m


# --------------------------------------------------------------------------- frames


def _sensor_to_ref(tables: NuScenesTables, sd: dict, ref_from_global: np.ndarray) -> np.ndarray:
    """(4, 4) sensor frame of this sweep -> reference ego frame, through the global frame."""
    cs = tables.follow("sample_data", sd, "calibrated_sensor_token", "calibrated_sensor")
    pose = tables.follow("sample_data", sd, "ego_pose_token", "ego_pose")
    return (ref_from_global @ pose_matrix(pose["translation"], pose["rotation"])
            @ pose_matrix(cs["translation"], cs["rotation"]))


def _sweeps(tables: NuScenesTables, sd: dict, nsweeps: int) -> list[dict]:
    """The key frame and up to nsweeps - 1 earlier sweeps of the same channel (prev links)."""
    out = [sd]
    while len(out) < nsweeps and out[-1].get("prev"):
        out.append(tables.follow("sample_data", out[-1], "prev", "sample_data"))
    return out


def _channel_points(tables: NuScenesTables, sd: dict, nsweeps: int, ref_from_global: np.ndarray, ref_time: float,
                    filters: dict) -> tuple[list[np.ndarray], int]:
    chunks, dropped = [], 0
    for sweep in _sweeps(tables, sd, nsweeps):
        pcd, n_bad = drop_nonfinite(read_radar_pcd(tables.file(sweep)))
        dropped += n_bad
        dt = ref_time - 1e-6 * sweep["timestamp"]  # positive for past sweeps, as the devkit's time_lag
        chunks.append(radar_features(filter_radar_points(pcd, **filters),
                                     _sensor_to_ref(tables, sweep, ref_from_global), dt))
    return chunks, dropped


def _sample_time(tables: NuScenesTables, ann: dict) -> float:
    return 1e-6 * tables.follow("sample_annotation", ann, "sample_token", "sample")["timestamp"]


def annotation_velocity(tables: NuScenesTables, ann: dict, max_time_diff: float = 1.5) -> np.ndarray:
    """Global (vx, vy, vz) from the prev/next annotations (devkit box_velocity); NaN when unknown."""
    ann = tables.check("sample_annotation", ann)
    first = tables.follow("sample_annotation", ann, "prev", "sample_annotation") if ann.get("prev") else ann
    last = tables.follow("sample_annotation", ann, "next", "sample_annotation") if ann.get("next") else ann
    if first is last:
        return np.full(3, np.nan)
    span = _sample_time(tables, last) - _sample_time(tables, first)
    # a centred difference spans two sample intervals, so it may be twice as long
    limit = max_time_diff * (2 if ann.get("prev") and ann.get("next") else 1)
    if span <= 0 or span > limit:
        return np.full(3, np.nan)
    return (np.asarray(last["translation"], np.float64) - np.asarray(first["translation"], np.float64)) / span


def annotation_points(ann: dict) -> int:
    """The devkit's num_pts: lidar + radar points in the box (load_gt); -1 (unknown, kept) unless the
    table gives both counts, since a box with 0 radar points may still hold lidar points."""
    if "num_lidar_pts" in ann and "num_radar_pts" in ann:
        return ann["num_lidar_pts"] + ann["num_radar_pts"]
    return -1


def _boxes(tables: NuScenesTables, sample_token: str, ego_from_global: np.ndarray,
           classes: Sequence[str] | None) -> tuple[Boxes, dict]:
    rows, unmapped = [], 0
    for ann in tables.annotations(sample_token):
        name = DETECTION_MAPPING.get(tables.category_name(ann))
        if name is None or (classes is not None and name not in classes):
            unmapped += 1
            continue
        rot = ego_from_global[:3, :3] @ quaternion_to_matrix(ann["rotation"])
        centre = ego_from_global[:3, :3] @ np.asarray(ann["translation"], np.float64) + ego_from_global[:3, 3]
        vel = ego_from_global[:3, :3] @ annotation_velocity(tables, ann)
        rows.append((centre, ann["size"], matrix_yaw(rot), vel[:2], name, annotation_points(ann)))
    if not rows:
        return Boxes.empty(), {"dropped_annotations": unmapped, "velocity_known": np.zeros(0, bool)}
    centre, size, yaw, vel, names, num_pts = zip(*rows)
    vel = np.array(vel, np.float64)
    known = np.all(np.isfinite(vel), axis=1)
    f32 = np.float32
    boxes = Boxes(np.array(centre, f32), np.array(size, f32), np.array(yaw, f32),
                  np.where(known[:, None], vel, 0.0).astype(f32), np.array(names, dtype="<U32"),
                  np.array(num_pts, np.int64))
    return boxes, {"dropped_annotations": unmapped, "velocity_known": known}


def read_nuscenes_frame(tables, sample_token: str, nsweeps: int = 1, channels: Sequence[str] = RADAR_CHANNELS,
                        ref_channel: str = "LIDAR_TOP", classes: Sequence[str] | None = None,
                        invalid_states: Iterable[int] = DEFAULT_INVALID_STATES,
                        dynprop_states: Iterable[int] = DEFAULT_DYNPROP_STATES,
                        ambig_states: Iterable[int] = DEFAULT_AMBIG_STATES) -> Frame:
    """One sample: radar points of `channels` and detection boxes, in the reference ego frame.

    tables: a NuScenesTables or a dataroot path. The reference is the ego pose of ref_channel's key
    frame (LIDAR_TOP, as the devkit's multi-sweep loader), else of the first radar channel present.
    dt = reference time - sweep time in seconds. Boxes keep the devkit detection names (car, truck,
    bus, trailer, construction_vehicle, pedestrian, motorcycle, bicycle, traffic_cone, barrier),
    optionally restricted to `classes`; velocities unknown to the devkit are zeros (meta velocity_known).
    boxes.num_pts is the devkit's num_lidar_pts + num_radar_pts (-1 where the table lacks them): the
    metric drops ground truth with 0, as the devkit's filter_eval_boxes does.

    A corrupt or mistyped table raises ValueError naming the table file, record and field; a
    sample_data file that is missing raises FileNotFoundError naming its record.
    """
    if not isinstance(tables, NuScenesTables):
        tables = NuScenesTables(tables)
    tables.get("sample", sample_token)
    ref_sd, ref_name = _reference(tables, sample_token, ref_channel, channels)
    ref_pose = tables.follow("sample_data", ref_sd, "ego_pose_token", "ego_pose")
    ref_from_global = pose_matrix(ref_pose["translation"], ref_pose["rotation"], inverse=True)
    filters = dict(invalid_states=invalid_states, dynprop_states=dynprop_states, ambig_states=ambig_states)
    chunks, dropped, per_channel = [], 0, {}
    for channel in channels:
        sd = tables.key_frame(sample_token, channel)
        if sd is None:
            continue
        pts, n_bad = _channel_points(tables, sd, nsweeps, ref_from_global, 1e-6 * ref_sd["timestamp"], filters)
        chunks += pts
        dropped += n_bad
        per_channel[channel] = int(sum(len(p) for p in pts))
    points = np.concatenate(chunks) if chunks else np.zeros((0, len(NUSCENES_FEATURES)), np.float32)
    boxes, box_meta = _boxes(tables, sample_token, ref_from_global, classes)
    meta = {"dropped_nonfinite": dropped, "ref_channel": ref_name, "timestamp": ref_sd["timestamp"],
            "points_per_channel": per_channel, **box_meta}
    return Frame(points, NUSCENES_FEATURES, boxes, frame_id=sample_token, source="nuscenes", meta=meta)


def _reference(tables: NuScenesTables, sample_token: str, ref_channel: str,
               channels: Sequence[str]) -> tuple[dict, str]:
    for name in (ref_channel, *channels):
        sd = tables.key_frame(sample_token, name)
        if sd is not None:
            return sd, name
    raise ValueError(f"{tables.path('sample_data')}: sample {sample_token!r} has no key-frame record for "
                     f"{ref_channel} or {tuple(channels)}")


__all__ = ["RADAR_FIELDS", "RADAR_CHANNELS", "NUSCENES_FEATURES", "DETECTION_MAPPING", "read_radar_pcd",
           "write_radar_pcd", "drop_nonfinite", "filter_radar_points", "radar_features", "quaternion_to_matrix",
           "matrix_yaw", "pose_matrix", "NuScenesTables", "list_samples", "annotation_velocity",
           "annotation_points", "read_nuscenes_frame"]

"""The nuScenes detection submission format: validation, JSON I/O and conversion to `Boxes`.

A box is a dict with ``translation``, ``size`` (w, l, h), ``rotation`` quaternion (w, x, y, z),
``velocity`` (vx, vy), ``detection_name``, ``detection_score`` and ``attribute_name`` (ground truth
may add ``num_pts`` and have no score); a file is ``{"meta": {...}, "results": {sample_token: [box, ...]}}``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any, Mapping, Sequence

import numpy as np

from ..core import atomic
from ..boxes.structures import Boxes

DETECTION_NAMES = ("car", "truck", "bus", "trailer", "construction_vehicle", "pedestrian", "motorcycle",
                   "bicycle", "traffic_cone", "barrier")
ATTRIBUTE_NAMES = ("pedestrian.moving", "pedestrian.sitting_lying_down", "pedestrian.standing",
                   "cycle.with_rider", "cycle.without_rider", "vehicle.moving", "vehicle.parked", "vehicle.stopped")
# detection_cvpr_2019: evaluation range per class, metres from the ego in the ground plane.
MAX_BOXES_PER_SAMPLE = 500
MAX_NUM_PTS = 2**31 - 1  # points in one box: any real count, and it fits the int64 arrays it becomes
META_KEYS = ("use_camera", "use_lidar", "use_radar", "use_map", "use_external")


def yaw_to_quaternion(yaw: float) -> list[float]:
    """Rotation by ``yaw`` about +z as a (w, x, y, z) quaternion, the submission's ``rotation``."""
    return [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]


def quaternion_to_yaw(q: Sequence[float]) -> float:
    """Heading of the rotated +x axis in the ground plane (the devkit's quaternion_yaw); q need not be unit."""
    w, x, y, z = (float(v) for v in q)
    return float(np.arctan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z))



_PLAIN_NUMBERS = {int, float}


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _is_finite(v: Any) -> bool:
    """A number that is a finite float; a JSON integer too large for a float is not."""
    try:
        return _is_number(v) and math.isfinite(float(v))
    except OverflowError:
        return False


def _vector(entry: Mapping, field: str, n: int, fail, finite: bool = True) -> list[float]:
    v = entry.get(field)
    v = v.tolist() if isinstance(v, np.ndarray) else v
    if not isinstance(v, (list, tuple)) or len(v) != n:
        fail(field, f"must be a list of {n} numbers; got {v!r}")
    if not finite:  # velocity: NaN (JSON null) means unknown, as in the devkit's ground truth
        v = [math.nan if x is None else x for x in v]
    # Fast path for plain JSON numbers; bools (an int subclass) and strings fall to the exact check and fail.
    if not set(map(type, v)) <= _PLAIN_NUMBERS and not all(_is_number(x) for x in v):
        fail(field, f"must be a list of {n} numbers; got {v!r}")
    try:
        out = [float(x) for x in v]
    except OverflowError:  # a JSON integer beyond the float range
        fail(field, f"must be a list of {n} numbers within the float range; got {v!r:.200}")
    if finite and not all(map(math.isfinite, out)):
        fail(field, f"must be a list of {n} finite numbers; got {v!r:.200}")
    return out


def _check_entry(entry: Any, token: str, i: int, source: str, is_gt: bool, names) -> dict:
    """One box: returns a normalised copy, or raises ValueError naming the file, sample token and field."""
    def fail(field, problem):
        raise ValueError(f"{source}: sample {token!r}, box {i}: field {field!r} {problem}")

    if not isinstance(entry, Mapping):
        fail("<box>", f"must be a JSON object; got {type(entry).__name__}")
    if entry.get("sample_token") != token:
        fail("sample_token", f"must equal the sample it is listed under; got {entry.get('sample_token')!r}")
    out = {"sample_token": token, "translation": _vector(entry, "translation", 3, fail),
           "size": _vector(entry, "size", 3, fail), "rotation": _vector(entry, "rotation", 4, fail),
           "velocity": _vector(entry, "velocity", 2, fail, finite=False)}
    if min(out["size"]) <= 0:
        fail("size", f"must be positive (w, l, h); got {out['size']}")
    if not any(out["rotation"]):
        fail("rotation", "must be a non-zero (w, x, y, z) quaternion")
    name = entry.get("detection_name")
    if not isinstance(name, str) or not name or (names is not None and name not in names):
        fail("detection_name", f"must be one of {list(names) if names else 'non-empty strings'}; got {name!r}")
    out["detection_name"] = name
    score = entry.get("detection_score", -1.0 if is_gt else None)
    if not _is_finite(score):
        fail("detection_score", f"must be a finite number; got {score!r}")
    out["detection_score"] = float(score)
    attr = entry.get("attribute_name", "")
    if attr != "" and attr not in ATTRIBUTE_NAMES:
        fail("attribute_name", f"must be '' or one of {list(ATTRIBUTE_NAMES)}; got {attr!r}")
    out["attribute_name"] = attr
    num_pts = entry.get("num_pts", -1)
    if not isinstance(num_pts, (int, np.integer)) or isinstance(num_pts, bool) or not -1 <= num_pts <= MAX_NUM_PTS:
        fail("num_pts", f"must be an integer from -1 (unknown) to {MAX_NUM_PTS}; got {num_pts!r}")
    out["num_pts"] = int(num_pts)
    if "ego_translation" in entry:
        out["ego_translation"] = _vector(entry, "ego_translation", 3, fail)
    return out


def validate_results(results: Any, source: str = "<results>", is_gt: bool = False,
                     detection_names: Sequence[str] | None = DETECTION_NAMES) -> dict[str, list]:
    """Checks ``{sample_token: [box, ...]}`` and returns normalised copies (floats, defaults filled in:
    GT score -1 and num_pts -1 as the devkit's loaders set them). ``detection_names=None`` accepts any class."""
    if not isinstance(results, Mapping):
        raise ValueError(f"{source}: field 'results' must map sample tokens to lists of boxes")
    out = {}
    for token, boxes in results.items():
        if not isinstance(boxes, list):
            raise ValueError(f"{source}: sample {token!r}: field 'results' entry must be a list of boxes")
        out[token] = [_check_entry(b, token, i, source, is_gt, detection_names) for i, b in enumerate(boxes)]
    return out


def _check_meta(meta: Any, source: str) -> dict:
    if not isinstance(meta, Mapping):
        raise ValueError(f"{source}: field 'meta' must be an object with {list(META_KEYS)}")
    for key in META_KEYS:
        if key in meta and not isinstance(meta[key], bool):
            raise ValueError(f"{source}: field 'meta.{key}' must be true or false; got {meta[key]!r}")
    return dict(meta)


def read_submission(path, is_gt: bool = False, max_boxes_per_sample: int | None = MAX_BOXES_PER_SAMPLE,
                    detection_names: Sequence[str] | None = DETECTION_NAMES) -> tuple[dict[str, list], dict]:
    """Reads a submission (or GT in the same format) -> (results, meta); ValueError says what is wrong where.

    Predictions need ``meta`` and at most ``max_boxes_per_sample`` boxes per sample (the devkit asserts both);
    ground truth may omit ``meta``, ``detection_score`` and ``num_pts``."""
    source = str(path)
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
        raise ValueError(f"{source}: not valid JSON ({type(e).__name__}: {e})") from None
    if not isinstance(data, Mapping) or "results" not in data:
        raise ValueError(f"{source}: field 'results' is missing")
    if "meta" not in data and not is_gt:
        raise ValueError(f"{source}: field 'meta' is missing")
    meta = _check_meta(data.get("meta", {}), source)
    results = validate_results(data["results"], source, is_gt, detection_names)
    if not is_gt and max_boxes_per_sample is not None:
        for token, boxes in results.items():
            if len(boxes) > max_boxes_per_sample:
                raise ValueError(f"{source}: sample {token!r}: field 'results' has {len(boxes)} boxes; "
                                 f"at most {max_boxes_per_sample} are allowed")
    return results, meta


def _json_box(box: Mapping) -> dict:
    out = {k: box[k] for k in ("sample_token", "translation", "size", "rotation")}
    out["velocity"] = [None if math.isnan(v) else v for v in box["velocity"]]
    out.update({k: box[k] for k in ("detection_name", "detection_score", "attribute_name")})
    if box.get("num_pts", -1) != -1:
        out["num_pts"] = box["num_pts"]
    if "ego_translation" in box:
        out["ego_translation"] = box["ego_translation"]
    return out


def write_submission(path, results: Mapping, meta: Mapping | None = None, is_gt: bool = False) -> None:
    """Writes ``{"meta": ..., "results": ...}``; meta defaults to a radar-only entry (use_radar true)."""
    meta = _check_meta(dict(meta) if meta is not None else
                       {**{k: False for k in META_KEYS}, "use_radar": True}, str(path))
    results = _as_results(results, is_gt)
    payload = {"meta": meta, "results": {t: [_json_box(b) for b in boxes] for t, boxes in results.items()}}
    atomic.write_text(path, json.dumps(payload))


def boxes_to_entries(sample_token: str, boxes, scores=None, attribute_names=None, num_pts=None) -> list[dict]:
    """The project's ``Boxes`` (+ scores) -> submission boxes; no scores means ground truth (score -1).

    ``num_pts`` defaults to the boxes' own counts (``Boxes.num_pts``, set by the nuScenes reader), else -1."""
    num_pts = getattr(boxes, "num_pts", None) if num_pts is None else num_pts
    entries = []
    for i in range(len(boxes)):
        entries.append({
            "sample_token": sample_token,
            "translation": [float(v) for v in boxes.center[i]], "size": [float(v) for v in boxes.size[i]],
            "rotation": yaw_to_quaternion(float(boxes.yaw[i])), "velocity": [float(v) for v in boxes.velocity[i]],
            "detection_name": str(boxes.names[i]),
            "detection_score": -1.0 if scores is None else float(scores[i]),
            "attribute_name": "" if attribute_names is None else str(attribute_names[i]),
            "num_pts": -1 if num_pts is None else int(num_pts[i])})
    return entries


def entries_to_boxes(entries: Sequence[Mapping]):
    """Submission boxes -> (``Boxes``, scores (M,) float32); yaw from the quaternion, unknown velocity -> 0;
    ``num_pts`` (-1 where absent) kept when any box has a count."""
    if not entries:
        return Boxes.empty(), np.zeros((0,), np.float32)
    f32 = lambda key: np.array([e[key] for e in entries], np.float32)  # noqa: E731
    boxes = Boxes(f32("translation"), f32("size"),
                  np.array([quaternion_to_yaw(e["rotation"]) for e in entries], np.float32),
                  np.nan_to_num(f32("velocity")), np.array([e["detection_name"] for e in entries]))
    counts = np.array([e.get("num_pts", -1) for e in entries], np.int64)
    if (counts != -1).any():
        boxes = dataclasses.replace(boxes, num_pts=counts)
    return boxes, np.array([e.get("detection_score", -1.0) for e in entries], np.float32)


def _as_results(data: Mapping, is_gt: bool) -> dict[str, list]:
    """Accepts lists of box dicts, ``Boxes`` or ``(Boxes, scores)`` per sample; returns validated box dicts."""
    out = {}
    for token, value in data.items():
        if isinstance(value, tuple) and len(value) == 2 and hasattr(value[0], "center"):
            value = boxes_to_entries(token, value[0], value[1])
        elif hasattr(value, "center"):
            value = boxes_to_entries(token, value)
        out[token] = value
    return validate_results(out, "<in memory>", is_gt, detection_names=None)

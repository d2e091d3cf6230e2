"""GeoJSON (RFC 7946) for placed objects and ego tracks: the one place the project builds it, for
the drive outputs (export.py) and the map service alike.

- `object_features(batch)`: one Feature per placed object of a frame batch (the exchange format,
  issue25 notes): geometry Point [lon, lat, alt] (RFC 7946 order: longitude first); properties
  class, score, time (UNIX s), time_iso (UTC ISO 8601 with milliseconds and "Z"; null when the
  time is past year 9999 or otherwise no date), depth_m, x_m,
  device, frame, box.
- `track_features(egos)`: one Feature per device from {device: [(time, lon, lat), ...]}: geometry
  LineString of [lon, lat] in time order, properties device. A LineString needs two or more
  positions (RFC 7946 §3.1.4), so a device seen once gets a Point, and one never seen none.
- `feature_collection(features)`: the FeatureCollection around them.
Every number must be finite: JSON has no NaN, and a reader would reject the file.
"""

from __future__ import annotations

import datetime
import math

OBJECT_KEYS = ("class", "score", "box", "depth_m", "x_m", "lat", "lon", "alt")


def _finite(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where} = {value!r}; expected a finite number")
    return float(value)


def time_iso(t: float) -> str | None:
    """UNIX seconds -> '2024-05-01T12:00:00.250Z' (UTC); None for a time no calendar date holds
    (a Unix time in milliseconds stored by an older service: the feature is still served, and
    its "time" still says what was stored)."""
    try:
        stamp = datetime.datetime.fromtimestamp(float(t), datetime.timezone.utc)
    except (OverflowError, OSError, ValueError):
        return None
    return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def object_features(batch: dict) -> list[dict]:
    """The batch's placed objects as GeoJSON Point Features (module docstring)."""
    for key in ("device", "frame", "time", "objects"):
        if key not in batch:
            raise ValueError(f"batch lacks {key!r}; expected the frame-batch fields device, frame, time, objects")
    t = _finite(batch["time"], "batch time")
    out = []
    for k, obj in enumerate(batch["objects"]):
        where = f"batch {batch.get('batch_id', batch['frame'])!s} objects[{k}]"
        missing = [key for key in OBJECT_KEYS if key not in obj]
        if missing:
            raise ValueError(f"{where} lacks {missing}; expected the placed-object keys {list(OBJECT_KEYS)}")
        lon, lat, alt = (_finite(obj[key], f"{where}.{key}") for key in ("lon", "lat", "alt"))
        if not isinstance(obj["box"], (list, tuple)) or len(obj["box"]) != 4:
            raise ValueError(f"{where}.box = {obj['box']!r}; expected [x1, y1, x2, y2]")
        box = [_finite(v, f"{where}.box") for v in obj["box"]]
        out.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, alt]},
                    "properties": {"class": str(obj["class"]), "score": _finite(obj["score"], f"{where}.score"),
                                   "time": t, "time_iso": time_iso(t),
                                   "depth_m": _finite(obj["depth_m"], f"{where}.depth_m"),
                                   "x_m": _finite(obj["x_m"], f"{where}.x_m"), "device": str(batch["device"]),
                                   "frame": str(batch["frame"]), "box": box}})
    return out


def track_features(egos: dict) -> list[dict]:
    """{device: [(time, lon, lat), ...]} -> one Feature per device with a position (module docstring)."""
    out = []
    for device, points in egos.items():
        pts = sorted((_finite(t, f"track {device} time"), _finite(lon, f"track {device} lon"),
                      _finite(lat, f"track {device} lat")) for t, lon, lat in points)
        coords = [[lon, lat] for _, lon, lat in pts]
        if not coords:
            continue
        geometry = {"type": "LineString", "coordinates": coords} if len(coords) > 1 else \
            {"type": "Point", "coordinates": coords[0]}
        out.append({"type": "Feature", "geometry": geometry, "properties": {"device": str(device)}})
    return out


def feature_collection(features) -> dict:
    return {"type": "FeatureCollection", "features": list(features)}

"""A drive's outputs from its frame batches (the exchange format), each file written atomically
(core/atomic.py: a reader sees the old file or the new one, never half of one):

- <stem>.geojson: one FeatureCollection with a Point Feature per placed object and a track
  Feature per device (geojson.py);
- <stem>.csv: one row per placed object, columns CSV_COLUMNS (the box as x1, y1, x2, y2 pixel
  edges; time in UNIX seconds as in the batch);
- <stem>.png: the top-view map (map_png.py), with ground-truth objects as hollow markers when
  `truth` is given.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from ..core import atomic
from .geojson import feature_collection, object_features, track_features
from .map_png import draw_map

CSV_COLUMNS = ("device", "frame", "time", "class", "score", "depth_m", "x_m", "lat", "lon", "alt",
               "x1", "y1", "x2", "y2")


def ego_tracks(batches: list[dict]) -> dict[str, list[tuple[float, float, float]]]:
    """{device: [(time, lon, lat), ...]}: what geojson.track_features draws."""
    egos: dict[str, list] = {}
    for b in batches:
        egos.setdefault(str(b["device"]), []).append((float(b["time"]), float(b["ego"]["lon"]), float(b["ego"]["lat"])))
    return egos


def drive_geojson(batches: list[dict]) -> dict:
    return feature_collection([f for b in batches for f in object_features(b)] + track_features(ego_tracks(batches)))


def drive_csv(batches: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for b in batches:
        for o in b["objects"]:
            writer.writerow([b["device"], b["frame"], repr(float(b["time"])), o["class"], repr(float(o["score"])),
                             repr(float(o["depth_m"])), repr(float(o["x_m"])), repr(float(o["lat"])),
                             repr(float(o["lon"])), repr(float(o["alt"]))] + [repr(float(v)) for v in o["box"]])
    return buf.getvalue()


def write_drive_outputs(out_dir, batches: list[dict], *, stem: str = "drive", truth: list[dict] | None = None,
                        origin=None, png: bool = True) -> dict[str, Path]:
    """Write <stem>.geojson, <stem>.csv and (png=True) <stem>.png under out_dir; returns their paths."""
    out_dir = Path(out_dir)
    paths = {"geojson": out_dir / f"{stem}.geojson", "csv": out_dir / f"{stem}.csv"}
    atomic.write_json(paths["geojson"], drive_geojson(batches))
    atomic.write_text(paths["csv"], drive_csv(batches))
    if png:
        paths["png"] = out_dir / f"{stem}.png"
        draw_map(batches, paths["png"], origin=origin, truth=truth)
    return paths

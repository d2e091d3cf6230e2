"""geo.geojson / geo.export / geo.map_png: a drive's GeoJSON, CSV and PNG map from frame batches."""

import csv
import io
import json
import math

import numpy as np
import pytest
from PIL import Image

from dsfec_jax.geo.export import CSV_COLUMNS, write_drive_outputs
from dsfec_jax.geo.geodesy import enu_to_geodetic
from dsfec_jax.geo.geojson import feature_collection, object_features, time_iso, track_features
from dsfec_jax.geo.map_png import draw_map
from dsfec_jax.geo.placement import Placer, frame_batch

ORIGIN = (49.0069, 8.4037, 115.0)
T0 = 1_700_000_000.0


def drive_batches(device="dev-01", frames=12, east=0.0):
    """An ego driving north at 10 m/s, placing a car 15 m ahead and a pedestrian to its right."""
    depth = np.full((60, 100), np.inf)
    depth[20:40, 40:60] = 15.0
    depth[25:45, 80:90] = 8.0
    placer = Placer(fx=50.0, cx=50.0, origin=ORIGIN)
    out = []
    for j in range(frames):
        ego_enu = np.array([east, 10.0 * j, 1.4])
        lat, lon, alt = enu_to_geodetic(ego_enu, ORIGIN)
        objects, _ = placer.place([[40, 20, 60, 40], [80, 25, 90, 45]], ["car", "pedestrian"], [0.9, 0.6], depth,
                                  ego_enu, 0.0)
        ego = {"lat": float(lat), "lon": float(lon), "alt": float(alt), "heading_deg": 0.0}
        out.append(frame_batch(device, f"{j:06d}", T0 + 0.1 * j, ego, objects))
    return out


def test_object_features_follow_the_exchange_format():
    batch = drive_batches(frames=1)[0]
    feats = object_features(batch)
    assert len(feats) == 2
    f = feats[0]
    assert f["type"] == "Feature" and f["geometry"]["type"] == "Point"
    o = batch["objects"][0]
    assert f["geometry"]["coordinates"] == [o["lon"], o["lat"], o["alt"]]      # RFC 7946: longitude first
    assert set(f["properties"]) == {"class", "score", "time", "time_iso", "depth_m", "x_m", "device", "frame", "box"}
    assert f["properties"]["time_iso"] == "2023-11-14T22:13:20.000Z" == time_iso(T0)
    bad = json.loads(json.dumps(batch))
    bad["objects"][1]["lat"] = math.nan
    with pytest.raises(ValueError, match=r"objects\[1\].lat = nan; expected a finite number"):
        object_features(bad)
    del bad["objects"][1]["lat"]
    with pytest.raises(ValueError, match=r"objects\[1\] lacks \['lat'\]"):
        object_features(bad)


def test_tracks_are_time_ordered_line_strings():
    feats = track_features({"a": [(2.0, 8.2, 49.2), (1.0, 8.1, 49.1), (3.0, 8.3, 49.3)], "b": [(1.0, 8.0, 49.0)],
                            "c": []})
    assert [f["properties"]["device"] for f in feats] == ["a", "b"]
    assert feats[0]["geometry"] == {"type": "LineString", "coordinates": [[8.1, 49.1], [8.2, 49.2], [8.3, 49.3]]}
    assert feats[1]["geometry"] == {"type": "Point", "coordinates": [8.0, 49.0]}   # one position: no line
    assert feature_collection(feats) == {"type": "FeatureCollection", "features": feats}


def test_drive_outputs_are_written_atomically_and_read_back(tmp_path):
    batches = drive_batches() + drive_batches("dev-02", frames=5, east=30.0)
    truth = [{"class": "car", "lat": o["lat"], "lon": o["lon"]} for o in batches[0]["objects"][:1]]
    paths = write_drive_outputs(tmp_path, batches, stem="run", truth=truth)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.geojson", "run.png"]   # no temp files

    gj = json.loads(paths["geojson"].read_text())
    assert gj["type"] == "FeatureCollection"
    kinds = [f["geometry"]["type"] for f in gj["features"]]
    assert kinds.count("Point") == 2 * 17 and kinds.count("LineString") == 2
    for f in gj["features"]:
        lon, lat = f["geometry"]["coordinates"][0] if f["geometry"]["type"] == "LineString" else \
            f["geometry"]["coordinates"][:2]
        assert abs(lat - ORIGIN[0]) < 0.01 and abs(lon - ORIGIN[1]) < 0.01

    rows = list(csv.DictReader(io.StringIO(paths["csv"].read_text())))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == 34
    first = batches[0]["objects"][0]
    assert rows[0]["device"] == "dev-01" and rows[0]["frame"] == "000000" and rows[0]["class"] == "car"
    assert [float(rows[0][k]) for k in ("lat", "lon", "x1", "y2")] == [first["lat"], first["lon"], 40.0, 40.0]
    assert float(rows[0]["time"]) == T0

    image = np.asarray(Image.open(paths["png"]).convert("RGB"))
    assert image.shape == (900, 900, 3)
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20            # not blank
    car_blue = np.array([31, 119, 180])                                 # tab10's first colour: 'car'
    assert np.sum(np.abs(image.astype(int) - car_blue).sum(-1) < 30) > 50


def test_the_map_has_its_own_size_and_needs_a_place():
    png = draw_map(drive_batches(frames=3), size_px=(400, 300), title="three frames")
    assert Image.open(io.BytesIO(png)).size == (400, 300)
    with pytest.raises(ValueError, match="at least one frame batch"):
        draw_map([])

"""The map service over real HTTP (uvicorn on a free localhost port): POST /detections' answers
(stored, duplicate, conflict, schema errors naming the field with nothing stored), the bbox/since
query, ego tracks, WAL mode, body limits, and exactly-once storage under concurrent re-posts.
The tests of storing and reading run on both stores (`fresh`: stores.py's `db`)."""

from __future__ import annotations

import http.client
import json
import sqlite3
import threading
import urllib.parse

import pytest

from service_helpers import DELETE, LAT0, LON0, T0, LiveServer, changed, get, make_batch, post, stored_rows
from stores import db  # noqa: F401 (pytest fixtures)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with LiveServer(tmp_path_factory.mktemp("svc") / "map.sqlite") as srv:
        yield srv


@pytest.fixture
def fresh(db):
    with LiveServer(db) as srv:
        yield srv


def test_a_batch_is_stored_once_and_a_repost_is_a_duplicate(fresh):
    batch = make_batch(0, n_objects=3)
    assert post(fresh.url, batch) == (201, {"status": "stored", "batch_id": "dev-01:000000", "objects": 3})
    reordered = dict(reversed(list(batch.items())))  # same content, keys in another order
    reordered["objects"][0]["score"] = float(batch["objects"][0]["score"])
    assert post(fresh.url, reordered)[0] == 200
    assert post(fresh.url, batch)[1]["status"] == "duplicate"
    health = get(fresh.url, "/health")[1]
    assert (health["batches"], health["objects"], health["devices"]) == (1, 3, 1)


def test_the_same_id_with_other_content_is_a_conflict(fresh):
    batch = make_batch(0, n_objects=2)
    assert post(fresh.url, batch)[0] == 201
    status, body = post(fresh.url, changed(batch, "objects.1.score", 0.01))
    assert status == 409 and "dev-01:000000" in body["detail"] and "different content" in body["detail"]
    objects = get(fresh.url, "/objects")[1]["features"]
    assert sorted(f["properties"]["score"] for f in objects) == sorted(o["score"] for o in batch["objects"])


BAD = [  # (path, value, the field the answer must name)
    ("objects.2.lat", 91.0, "objects.2.lat"),
    ("objects.0.lon", -180.5, "objects.0.lon"),
    ("objects.1.score", 1.5, "objects.1.score"),
    ("objects.1.box", [50.0, 20.0, 40.0, 60.0], "objects.1.box"),
    ("objects.0.box", [1.0, 2.0, 3.0], "objects.0.box"),
    ("objects.0.class", "", "objects.0.class"),
    ("objects.0.class", "   ", "objects.0.class"),
    ("objects.0.depth_m", -3.0, "objects.0.depth_m"),
    ("objects.0.colour", "red", "objects.0.colour"),
    ("ego.lat", "49.0", "ego.lat"),
    ("ego.heading_deg", True, "ego.heading_deg"),
    ("time", "2026-01-01", "time"),
    ("device", DELETE, "device"),
    ("batch_id", "", "batch_id"),
    ("objects", [{"class": "car"}], "objects.0.score"),
]


@pytest.mark.parametrize("path,value,field", BAD, ids=[f"{p}={v!r}" for p, v, _ in BAD])
def test_a_schema_error_names_the_field_and_stores_nothing(server, path, value, field):
    before = get(server.url, "/health")[1]
    status, body = post(server.url, changed(make_batch(7, n_objects=3), path, value))
    assert status == 422
    assert any(line.startswith(f"{field}:") for line in body["errors"]), body
    assert field in body["detail"]
    after = get(server.url, "/health")[1]
    assert (after["batches"], after["objects"]) == (before["batches"], before["objects"])


def test_non_finite_numbers_too_many_objects_and_non_json_are_refused(server):
    text = json.dumps(make_batch(8)).replace('"time": 1790000000.8', '"time": NaN').encode()
    assert b"NaN" in text
    status, body = post(server.url, text)
    assert status == 422 and body["errors"][0].startswith("time:")
    status, body = post(server.url, make_batch(9, n_objects=1001))
    assert status == 422 and body["errors"][0].startswith("objects:")
    status, body = post(server.url, b'{"batch_id": ')
    assert status == 422 and body["detail"] == "body: not valid JSON at character 13 (Expecting value)"
    status, body = post(server.url, b"")
    assert status == 422 and body["detail"].startswith("body:")
    assert get(server.url, "/health")[1]["batches"] == 0


def test_a_declared_oversize_body_is_a_413_and_a_small_chunked_body_is_read(server):
    """413 from the header, before any body is read; chunked bodies are bounded by the bytes read
    (test_hostile.py), so a small one is simply taken."""
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.putrequest("POST", "/detections")
    conn.putheader("Content-Type", "application/json")
    conn.putheader("Content-Length", str(2 * 1024 * 1024 + 1))
    conn.endheaders()
    reply = conn.getresponse()
    assert reply.status == 413 and json.loads(reply.read())["detail"].startswith("body: 2097153 bytes")
    conn.close()
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.request("POST", "/detections", body=iter([json.dumps(make_batch(1)).encode()]),
                 headers={"Content-Type": "application/json"}, encode_chunked=True)
    reply = conn.getresponse()
    assert reply.status == 201 and json.loads(reply.read())["batch_id"] == "dev-01:000001"
    conn.close()


def test_objects_filter_by_bbox_since_and_limit(fresh):
    # three devices: two near Karlsruhe at different times, one across the antimeridian
    assert post(fresh.url, make_batch(0, "a", n_objects=2, t=T0))[0] == 201
    assert post(fresh.url, make_batch(1, "a", n_objects=2, t=T0 + 100))[0] == 201
    assert post(fresh.url, make_batch(0, "b", n_objects=1, t=T0 + 50, lat=LAT0 + 1.0))[0] == 201
    assert post(fresh.url, make_batch(0, "c", n_objects=1, t=T0 + 60, lat=-17.0, lon=179.9999))[0] == 201

    def query(q):
        status, fc = get(fresh.url, "/objects" + q)
        assert status == 200 and fc["type"] == "FeatureCollection", fc
        return fc

    everything = query("")
    assert len(everything["features"]) == 6 and not everything["truncated"]
    times = [f["properties"]["time"] for f in everything["features"]]
    assert times == sorted(times, reverse=True)  # newest first
    f = everything["features"][0]
    assert f["geometry"]["type"] == "Point" and len(f["geometry"]["coordinates"]) == 3
    assert {"class", "score", "time", "time_iso", "depth_m", "x_m", "device", "frame", "box"} <= set(f["properties"])

    near_karlsruhe = f"?bbox={LON0 - 0.01},{LAT0 - 0.01},{LON0 + 0.01},{LAT0 + 0.01}"
    assert {f["properties"]["device"] for f in query(near_karlsruhe)["features"]} == {"a"}
    assert len(query(near_karlsruhe)["features"]) == 4
    assert len(query(near_karlsruhe + f"&since={T0 + 100}")["features"]) == 2
    assert len(query(f"?since={T0 + 50}")["features"]) == 4
    across = query("?bbox=179.9,-18,-179.9,-16")  # minlon > maxlon: the box crosses the antimeridian
    assert [f["properties"]["device"] for f in across["features"]] == ["c"]
    cut = query("?limit=3")
    assert len(cut["features"]) == 3 and cut["truncated"]


def test_since_accepts_iso_8601_and_reads_a_naive_time_as_utc(fresh):
    assert post(fresh.url, make_batch(0, t=1_000_000_000.0))[0] == 201  # 2001-09-09T01:46:40Z
    assert post(fresh.url, make_batch(1, t=1_000_000_100.0))[0] == 201
    for since, n in [("2001-09-09T01:46:40Z", 6), ("2001-09-09T01:46:41Z", 3), ("2001-09-09T01:46:41", 3),
                     ("2001-09-09T03:46:41+02:00", 3), ("1000000100.0", 3), ("2001-09-09T01:48:21Z", 0)]:
        assert len(get(fresh.url, f"/objects?since={urllib.parse.quote(since)}")[1]["features"]) == n, since


@pytest.mark.parametrize("query,name", [("bbox=1,2,3", "bbox"), ("bbox=a,b,c,d", "bbox"), ("bbox=0,10,1,5", "bbox"),
                                        ("bbox=0,0,200,1", "bbox"), ("since=yesterday", "since"),
                                        ("since=nan", "since"), ("limit=0", "limit"), ("limit=x", "limit")])
def test_a_bad_query_parameter_is_a_400_naming_it(server, query, name):
    status, body = get(server.url, f"/objects?{query}")
    assert status == 400 and body["detail"].startswith(f"{name}:"), body


def test_tracks_are_per_device_in_time_order(fresh):
    for i in (2, 0, 1):  # posted out of order: the track still runs in time order
        assert post(fresh.url, make_batch(i, "dev-a", n_objects=0))[0] == 201
    assert post(fresh.url, make_batch(0, "dev-b", n_objects=1, lon=LON0 + 0.01))[0] == 201
    fc = get(fresh.url, "/tracks")[1]
    tracks = {f["properties"]["device"]: f["geometry"] for f in fc["features"]}
    assert set(tracks) == {"dev-a", "dev-b"} and tracks["dev-a"]["type"] == "LineString"
    lats = [c[1] for c in tracks["dev-a"]["coordinates"]]
    assert lats == pytest.approx([LAT0, LAT0 + 1e-4, LAT0 + 2e-4])
    assert tracks["dev-a"]["coordinates"][0][0] == pytest.approx(LON0)
    assert tracks["dev-b"] == {"type": "Point", "coordinates": [LON0 + 0.01, LAT0]}  # one position: no line
    recent = get(fresh.url, f"/tracks?since={T0 + 0.15}&device=dev-a")[1]["features"]
    assert [f["geometry"]["coordinates"] for f in recent] == [[LON0, LAT0 + 2e-4]]


def test_the_database_is_in_wal_mode(tmp_path):
    with LiveServer(tmp_path / "map.sqlite") as fresh:
        assert post(fresh.url, make_batch(0))[0] == 201
        assert get(fresh.url, "/health")[1]["journal_mode"] == "wal"
    with sqlite3.connect(fresh.db_path) as conn:  # the mode is a property of the file, not of one connection
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert conn.execute("SELECT COUNT(*) FROM objects").fetchone()[0] == 3


def test_concurrent_reposts_store_every_batch_exactly_once(fresh):
    """8 threads post 40 batches, every batch twice from two threads at once: one 201 per id."""
    batches = [make_batch(i, f"dev-{i % 4}", n_objects=i % 5) for i in range(40)]
    statuses: dict[str, list[int]] = {b["batch_id"]: [] for b in batches}
    lock = threading.Lock()

    def worker(k):
        for b in batches[k % 4::4] if k < 4 else reversed(batches[k % 4::4]):
            status = post(fresh.url, b)[0]
            with lock:
                statuses[b["batch_id"]].append(status)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(8)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert all(sorted(s) == [200, 201] for s in statuses.values()), statuses
    assert stored_rows(fresh.db_path, "SELECT COUNT(*), COUNT(DISTINCT batch_id) FROM batches") == [(40, 40)]
    assert stored_rows(fresh.db_path, "SELECT COUNT(*) FROM objects") == [(sum(i % 5 for i in range(40)),)]


def test_the_map_page_and_its_script_are_served(server):
    status, page = get(server.url, "/")
    assert status == 200 and "<canvas" in page and "static/map.js" in page
    status, script = get(server.url, "/static/map.js")
    assert status == 200 and "dataset.objects" in script


def test_objects_after_a_cursor_are_only_the_ones_stored_since(fresh):
    for i in (5, 6):
        assert post(fresh.url, make_batch(i, n_objects=2))[0] == 201
    first = get(fresh.url, "/objects")[1]
    assert len(first["features"]) == 4 and first["cursor"] == 4
    assert post(fresh.url, make_batch(1, n_objects=3))[0] == 201  # older in time, stored later (a queue drained)
    new = get(fresh.url, f"/objects?after={first['cursor']}")[1]
    assert [f["properties"]["frame"] for f in new["features"]] == ["frame-000001"] * 3 and new["cursor"] == 7
    idle = get(fresh.url, f"/objects?after={new['cursor']}")[1]
    assert idle["features"] == [] and idle["cursor"] == 7 and not idle["truncated"]
    paged = get(fresh.url, "/objects?after=0&limit=3")[1]
    assert len(paged["features"]) == 3 and paged["truncated"] and paged["cursor"] == 3
    tracks = get(fresh.url, "/tracks")[1]
    assert tracks["cursor"] == 3 and get(fresh.url, "/tracks?after=2")[1]["features"][0]["geometry"]["type"] == "Point"

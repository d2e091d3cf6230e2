"""The operator's side of the map service: tokens issued from the command line (only hashes
stored), reads behind a read token, delete and export with an admin token, retention, the v1 ->
v2 schema migration keeping every row, and reads that survive a bad row already in a database."""

from __future__ import annotations

import hashlib
import json
import sqlite3
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest

from dsfec_jax.service import tokens
from dsfec_jax.service.app import Access
from dsfec_jax.service.schema import FrameBatch
from dsfec_jax.service.server import resolve_access
from dsfec_jax.service.store import Store, open_store
from service_helpers import LiveServer, get, make_batch, post, stored_rows
from stores import db, module_db  # noqa: F401 (pytest fixtures)


@pytest.fixture
def _cli(capsys):
    """`python -m dsfec_jax.service ARGS` in this process (a subprocess costs seconds of imports)."""
    from dsfec_jax.service.__main__ import main

    def run(*args: str) -> subprocess.CompletedProcess:
        try:
            code = main(list(args))
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else (print(exit_.code, file=sys.stderr) or 1)
        out = capsys.readouterr()
        return subprocess.CompletedProcess(args, code, out.out, out.err)
    return run


def test_token_commands_issue_list_and_revoke_and_store_only_hashes(db, _cli):
    db = str(db)
    out = _cli("token", "add", "--db", db, "--device", "cam-01", "--device", "cam-02", "--json")
    assert out.returncode == 0, out.stderr
    issued = json.loads(out.stdout)
    assert [(i["role"], i["device"]) for i in issued] == [("device", "cam-01"), ("device", "cam-02")]
    admin = _cli("token", "add", "--db", db, "--role", "admin")
    assert admin.returncode == 0 and admin.stdout.startswith("dsfec_") and "shown once" in admin.stderr
    stored = stored_rows(db, "SELECT sha256 FROM tokens")
    dump = "\n".join(map(str, stored_rows(db, "SELECT * FROM tokens")))
    if not db.startswith("postgresql://"):
        with sqlite3.connect(db) as conn:
            dump = "\n".join(conn.iterdump())
    assert {h for (h,) in stored} == {hashlib.sha256(t.encode()).hexdigest()
                                      for t in [i["token"] for i in issued] + [admin.stdout.strip()]}
    assert not any(i["token"].split("_", 2)[2] in dump for i in issued)  # no secret in the file
    assert _cli("token", "revoke", "--db", db, issued[0]["id"]).returncode == 0
    listed = json.loads(_cli("token", "list", "--db", db).stdout)
    assert [t["revoked"] is not None for t in listed] == [True, False, False]
    assert "no live token" in _cli("token", "revoke", "--db", db, issued[0]["id"]).stderr
    assert "needs --device" in _cli("token", "add", "--db", db).stderr


def test_no_auth_is_refused_off_loopback_and_reads_are_open_only_on_loopback():
    with pytest.raises(ValueError, match="--no-auth"):
        resolve_access("0.0.0.0", no_auth=True)
    assert resolve_access("127.0.0.1").open_reads and resolve_access("::1").open_reads
    assert not resolve_access("0.0.0.0").open_reads and not resolve_access("192.168.1.5").open_reads
    assert resolve_access("0.0.0.0", reads="open").open_reads and not resolve_access("127.0.0.1", reads="token").open_reads
    assert resolve_access("127.0.0.1").write_auth and "map.example.org" in resolve_access(
        "0.0.0.0", allowed_hosts=["map.example.org"]).allowed_hosts


@pytest.fixture(scope="module")
def closed(module_db):
    """A server with reads behind tokens, and its tokens (on each store)."""
    db = module_db
    store = open_store(db)
    names = {"dev-a": ("device", "dev-a"), "dev-b": ("device", "dev-b"), "reader": ("read", None), "admin": ("admin", None)}
    issued = {k: tokens.issue(store, *v)[1] for k, v in names.items()}
    store.close()
    with LiveServer(db, access=Access(open_reads=False)) as srv:
        srv.tokens = issued
        now = time.time()
        for i in range(6):
            for dev in ("dev-a", "dev-b"):
                assert post(srv.url, make_batch(i, dev, n_objects=2, t=now - 3600 * (6 - i)), token=issued[dev])[0] == 201
        srv.t0 = now
        yield srv


def test_reads_need_a_read_or_admin_token_when_configured(closed):
    for path in ("/objects", "/tracks"):
        assert get(closed.url, path)[0] == 401
        assert get(closed.url, path, token=closed.tokens["dev-a"])[0] == 403  # a device token does not read
        assert get(closed.url, path, token=closed.tokens["reader"])[0] == 200
        assert get(closed.url, path, token=closed.tokens["admin"])[0] == 200
    assert get(closed.url, "/health")[0] == 200 and get(closed.url, "/")[0] == 200  # no data in either


def _request(srv, method: str, path: str, token: str | None) -> tuple[int, bytes]:
    req = urllib.request.Request(srv.url + path, method=method,
                                 headers={"Authorization": f"Bearer {token}"} if token else {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def test_export_and_delete_need_an_admin_token(closed):
    for token in (None, closed.tokens["reader"], closed.tokens["dev-a"]):
        assert _request(closed, "GET", "/export", token)[0] in (401, 403)
        assert _request(closed, "DELETE", "/detections?device=dev-a", token)[0] in (401, 403)
    status, body = _request(closed, "GET", "/export?device=dev-b", closed.tokens["admin"])
    lines = [json.loads(line) for line in body.decode().splitlines()]
    assert status == 200 and [b["batch_id"] for b in lines] == [f"dev-b:{i:06d}" for i in range(6)]
    assert FrameBatch.model_validate(lines[0]).wire() == lines[0]  # the exchange format: re-postable
    assert _request(closed, "DELETE", "/detections", closed.tokens["admin"])[0] == 400  # no filter: refused
    cutoff = closed.t0 - 3600 * 3.5  # dev-a's frames 0, 1, 2
    status, body = _request(closed, "DELETE", f"/detections?device=dev-a&until={cutoff}", closed.tokens["admin"])
    assert status == 200 and json.loads(body)["deleted"] == {"batches": 3, "objects": 6}
    health = get(closed.url, "/health")[1]
    assert (health["batches"], health["objects"], health["devices"]) == (9, 18, 2)
    status, body = _request(closed, "DELETE", "/detections?device=dev-a", closed.tokens["admin"])
    assert json.loads(body)["deleted"]["batches"] == 3 and get(closed.url, "/health")[1]["devices"] == 1
    assert post(closed.url, make_batch(0, "dev-a", t=closed.t0), token=closed.tokens["dev-a"])[0] == 201  # posts go on


def test_retention_deletes_old_batches_in_bounded_transactions(db, monkeypatch):
    from dsfec_jax.service import sql_store

    monkeypatch.setattr(sql_store, "DELETE_CHUNK", 4)
    store = open_store(db)
    now = time.time()
    for i in range(10):
        store.put(FrameBatch.model_validate(make_batch(i, n_objects=1, t=now - 86400 * (10 - i))))  # 10..1 days old
    store.close()
    with LiveServer(db, access=Access(retention_days=3.5)) as srv:
        deadline = time.monotonic() + 5
        while get(srv.url, "/health")[1]["batches"] != 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert get(srv.url, "/health")[1]["batches"] == 3  # 3, 2 and 1 days old are kept
        assert [f["properties"]["frame"] for f in get(srv.url, "/objects")[1]["features"]] == \
            [f"frame-{i:06d}" for i in (9, 8, 7)]


V1_SCHEMA = """
CREATE TABLE batches (batch_id TEXT PRIMARY KEY, device TEXT NOT NULL, frame TEXT NOT NULL, time REAL NOT NULL,
    ego_lat REAL NOT NULL, ego_lon REAL NOT NULL, ego_alt REAL NOT NULL, ego_heading_deg REAL NOT NULL,
    n_objects INTEGER NOT NULL, content_sha256 TEXT NOT NULL, received REAL NOT NULL);
CREATE INDEX batches_time ON batches (time);
CREATE INDEX batches_device_time ON batches (device, time);
CREATE TABLE objects (id INTEGER PRIMARY KEY, batch_id TEXT NOT NULL REFERENCES batches (batch_id),
    idx INTEGER NOT NULL, class TEXT NOT NULL, score REAL NOT NULL, lat REAL NOT NULL, lon REAL NOT NULL,
    alt REAL NOT NULL, depth_m REAL NOT NULL, x_m REAL NOT NULL, box_x1 REAL NOT NULL, box_y1 REAL NOT NULL,
    box_x2 REAL NOT NULL, box_y2 REAL NOT NULL, time REAL NOT NULL, device TEXT NOT NULL, frame TEXT NOT NULL,
    UNIQUE (batch_id, idx));
CREATE INDEX objects_time ON objects (time);
CREATE INDEX objects_lat_lon ON objects (lat, lon);
PRAGMA user_version = 1;
"""


def _v1_hash(batch: dict) -> str:
    try:
        return FrameBatch.model_validate(batch).content_hash()
    except ValueError:  # a batch today's schema refuses (what an older service let in)
        return "0" * 64


def _v1_database(path, batches) -> None:
    """A database as the version-1 service wrote it (its schema, verbatim), holding `batches`."""
    with sqlite3.connect(path) as conn:
        conn.executescript(V1_SCHEMA)
        for b in batches:
            e = b["ego"]
            conn.execute("INSERT INTO batches VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                         (b["batch_id"], b["device"], b["frame"], b["time"], e["lat"], e["lon"], e["alt"],
                          e["heading_deg"], len(b["objects"]), _v1_hash(b), b["time"]))
            for i, o in enumerate(b["objects"]):
                conn.execute("INSERT INTO objects (batch_id, idx, class, score, lat, lon, alt, depth_m, x_m, box_x1,"
                             " box_y1, box_x2, box_y2, time, device, frame) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?,"
                             " ?, ?, ?, ?)", (b["batch_id"], i, o["class"], o["score"], o["lat"], o["lon"], o["alt"],
                                              o["depth_m"], o["x_m"], *o["box"], b["time"], b["device"], b["frame"]))


def test_a_version_1_database_is_migrated_keeping_every_row(tmp_path):
    posted = [make_batch(i, dev, n_objects=i % 3) for i in range(4) for dev in ("a", "b")]
    _v1_database(tmp_path / "v1.sqlite", posted)
    store = Store(tmp_path / "v1.sqlite")
    assert store.counts() == {"batches": 8, "objects": sum(i % 3 for i in range(4)) * 2, "devices": 2}
    assert sorted(store.export(), key=lambda b: (b["device"], b["batch_id"])) == \
        sorted(posted, key=lambda b: (b["device"], b["batch_id"]))
    assert store.put(FrameBatch.model_validate(posted[0])) == "duplicate"  # the stored hashes still match
    store.close()
    with sqlite3.connect(tmp_path / "v1.sqlite") as conn:
        assert conn.execute("PRAGMA user_version").fetchone()[0] == 2
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert not conn.execute("PRAGMA foreign_key_check").fetchall()
        assert {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'index'")} >= {
            "batches_time", "batches_device_time", "objects_time", "objects_lat_lon"}


def test_a_stored_row_with_an_absurd_time_does_not_break_reads(tmp_path):
    """An older service stored `time` 1e13 (a Unix time in ms x 10): every GET /objects was a 500."""
    posted = make_batch(0, n_objects=2)
    posted["time"] = 1e13
    _v1_database(tmp_path / "old.sqlite", [posted, make_batch(1, n_objects=1)])
    with LiveServer(tmp_path / "old.sqlite") as srv:
        status, fc = get(srv.url, "/objects")
        assert status == 200 and len(fc["features"]) == 3
        bad = [f["properties"] for f in fc["features"] if f["properties"]["time"] == 1e13]
        assert len(bad) == 2 and all(p["time_iso"] is None for p in bad)
        assert get(srv.url, "/tracks")[0] == 200


def test_dsfec_serve_takes_the_server_options_and_the_token_command():
    """One argument definition (service/options.py) behind `dsfec serve` and `python -m dsfec_jax.service`."""
    import argparse

    from dsfec_jax.cli_edge import add_commands

    p = argparse.ArgumentParser(prog="dsfec")
    add_commands(p.add_subparsers(dest="command"))
    a = p.parse_args(["serve", "--db", "m.sqlite", "--synchronous", "NORMAL", "--log-level", "debug", "--no-access-log",
                      "--allowed-host", "map.example.org", "--retention-days", "30", "--reads", "token"])
    assert (a.synchronous, a.log_level, a.access_log, a.allowed_host, a.retention_days, a.reads, a.admin) == \
        ("NORMAL", "debug", False, ["map.example.org"], 30.0, "token", None)
    assert p.parse_args(["serve", "--db", "m.sqlite"]).access_log  # access logs on by default
    b = p.parse_args(["serve", "token", "add", "--db", "m.sqlite", "--device", "cam-01"])
    assert (b.admin, b.token_action, b.device, b.db, b.role) == ("token", "add", ["cam-01"], "m.sqlite", "device")

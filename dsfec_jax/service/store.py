"""SQLite storage of frame batches and their placed objects (stdlib sqlite3, one file).

Durability: WAL journal with synchronous=FULL (the default), so a batch is on disk (WAL fsynced)
before the service answers 201; the device deletes its queued copy on that answer, so an
acknowledged batch survives a kill and a power loss. The fsync per commit bounds the write rate
(one commit at a time; the rate: docs/edge-and-map-service.md, re-measured by `python -m
dsfec_jax.edge.loadtest`). synchronous=NORMAL skips it:
still safe against a killed server process (the WAL is in the OS's page cache), but a power loss
or kernel crash may lose the last acknowledged batches. WAL lets readers (the map's GETs) run
beside the writer.

One transaction per batch (BEGIN IMMEDIATE ... COMMIT): a batch and all its objects are stored
together or not at all. Idempotency: a batch is keyed by (device, batch_id), so a batch id lives in
its device's namespace (with write tokens the device is the authenticated one: nobody else can
squat or collide with its ids); `content_sha256` is the hash of the validated batch: a re-post with
the same hash is a duplicate (nothing written), a different hash under the same key is a Conflict.

Threads: FastAPI runs sync endpoints in a thread pool, so every thread gets its own connection
(sqlite3 connections must not be shared across threads mid-statement). Writers go through one
lock: SQLite admits a single writer anyway, and a Python lock queues them fairly instead of
leaving them to SQLite's sleep-and-retry busy handler; busy_timeout still covers other processes
(a load test reading the file, a second server on the same DB, `dsfec serve token add`).

Objects carry their batch's time and device (denormalised) so the bbox/since query reads one
table through its indexes: (time) for "latest since", (lat, lon) for a small bounding box.
Batches and objects have AUTOINCREMENT ids that never go back (not even after a delete): the
map page's cursors ("what is new since id N"). The `devices` table keeps per-device counts,
updated in the same transaction as each insert or delete, so /health reads a few rows, not a
count over millions. `tokens` holds the sha256 of each access token (tokens.py), never a token.

Schema version 2 (version 1 keyed batches by batch_id alone and had no devices/tokens tables): an
older database is migrated in one transaction on open, keeping every row.
"""

from __future__ import annotations

import sqlite3
import threading
import time as _time
from contextlib import contextmanager
from pathlib import Path

from .schema import FrameBatch

SCHEMA_VERSION = 2
BUSY_TIMEOUT_S = 10.0
SYNCHRONOUS = ("FULL", "NORMAL")  # see the module docstring: power-loss safe, or crash safe and faster
DELETE_CHUNK = 500  # batches per delete transaction: a retention sweep never holds the writer for long

_TABLES = """
CREATE TABLE IF NOT EXISTS batches (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    device TEXT NOT NULL,
    batch_id TEXT NOT NULL,
    frame TEXT NOT NULL,
    time REAL NOT NULL,
    ego_lat REAL NOT NULL, ego_lon REAL NOT NULL, ego_alt REAL NOT NULL, ego_heading_deg REAL NOT NULL,
    n_objects INTEGER NOT NULL,
    content_sha256 TEXT NOT NULL,
    received REAL NOT NULL,
    UNIQUE (device, batch_id)
);
CREATE TABLE IF NOT EXISTS objects (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    device TEXT NOT NULL,
    batch_id TEXT NOT NULL,
    idx INTEGER NOT NULL,
    class TEXT NOT NULL,
    score REAL NOT NULL,
    lat REAL NOT NULL, lon REAL NOT NULL, alt REAL NOT NULL,
    depth_m REAL NOT NULL, x_m REAL NOT NULL,
    box_x1 REAL NOT NULL, box_y1 REAL NOT NULL, box_x2 REAL NOT NULL, box_y2 REAL NOT NULL,
    time REAL NOT NULL,
    frame TEXT NOT NULL,
    UNIQUE (device, batch_id, idx),
    FOREIGN KEY (device, batch_id) REFERENCES batches (device, batch_id)
);
CREATE TABLE IF NOT EXISTS devices (
    device TEXT PRIMARY KEY,
    batches INTEGER NOT NULL,
    objects INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS tokens (
    id TEXT PRIMARY KEY,
    sha256 TEXT NOT NULL,
    role TEXT NOT NULL CHECK (role IN ('device', 'read', 'admin')),
    device TEXT CHECK ((role = 'device') = (device IS NOT NULL)),
    created REAL NOT NULL,
    revoked REAL
);
"""
_INDEXES = """
CREATE INDEX IF NOT EXISTS batches_time ON batches (time);
CREATE INDEX IF NOT EXISTS batches_device_time ON batches (device, time);
CREATE INDEX IF NOT EXISTS objects_time ON objects (time);
CREATE INDEX IF NOT EXISTS objects_lat_lon ON objects (lat, lon);
"""
_BATCH_COLUMNS = ("device, batch_id, frame, time, ego_lat, ego_lon, ego_alt, ego_heading_deg, n_objects, "
                  "content_sha256, received")
_OBJECT_COLUMNS = ("device, batch_id, idx, class, score, lat, lon, alt, depth_m, x_m, box_x1, box_y1, box_x2, "
                   "box_y2, time, frame")
_MIGRATE_FROM_1 = f"""
ALTER TABLE objects RENAME TO objects_v1;
ALTER TABLE batches RENAME TO batches_v1;
DROP INDEX IF EXISTS batches_time; DROP INDEX IF EXISTS batches_device_time;
DROP INDEX IF EXISTS objects_time; DROP INDEX IF EXISTS objects_lat_lon;
{_TABLES}
INSERT INTO batches ({_BATCH_COLUMNS}) SELECT {_BATCH_COLUMNS} FROM batches_v1 ORDER BY received, rowid;
INSERT INTO objects ({_OBJECT_COLUMNS}) SELECT {_OBJECT_COLUMNS} FROM objects_v1 ORDER BY id;
DROP TABLE objects_v1;
DROP TABLE batches_v1;
"""
_COUNT_DEVICES = "INSERT INTO devices SELECT device, COUNT(*), SUM(n_objects) FROM batches GROUP BY device"


class Conflict(Exception):
    """The (device, batch id) is stored already, with different content."""


class Store:
    """The service's database. `put` stores a batch; `objects`, `tracks` and `export` read for the
    map and the operator; `delete` removes by device and time range."""

    def __init__(self, path: str | Path, synchronous: str = "FULL"):
        if synchronous not in SYNCHRONOUS:
            raise ValueError(f"synchronous={synchronous!r}; expected one of {SYNCHRONOUS}")
        self.path, self.synchronous = Path(path), synchronous
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        self._connections: list[sqlite3.Connection] = []
        self._registry_lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._init_schema()

    # -- connections -----------------------------------------------------------------------------
    def _open(self) -> sqlite3.Connection:
        # isolation_level=None: we issue BEGIN/COMMIT ourselves; check_same_thread=False only so
        # close() may close every thread's connection at shutdown (each is used by one thread).
        conn = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None, check_same_thread=False)
        with self._registry_lock:
            self._connections.append(conn)
        conn.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
        conn.execute(f"PRAGMA synchronous = {self.synchronous}")
        conn.execute("PRAGMA foreign_keys = ON")
        return conn

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = self._local.conn = self._open()
        return conn

    def _init_schema(self) -> None:
        try:
            conn = self._conn()
            mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
            version = conn.execute("PRAGMA user_version").fetchone()[0]
        except sqlite3.DatabaseError as e:
            self.close()
            raise ValueError(f"{self.path}: not a SQLite database the map service can use ({e})") from e
        if mode.lower() != "wal":
            raise RuntimeError(f"{self.path}: SQLite refused WAL mode (journal_mode={mode}); is it on a network file system?")
        if version not in (0, 1, SCHEMA_VERSION):
            raise ValueError(f"{self.path}: schema version {version}, this service reads versions 1 and {SCHEMA_VERSION}")
        if version == SCHEMA_VERSION:
            return
        # foreign_keys can only change outside a transaction; off while the tables are rebuilt
        conn.execute("PRAGMA foreign_keys = OFF")
        try:
            with self.transaction() as tx:
                tx.executescript_in_tx(_MIGRATE_FROM_1 if version == 1 else _TABLES)
                tx.executescript_in_tx(_INDEXES)
                if version == 1:
                    conn.execute(_COUNT_DEVICES)
                    broken = conn.execute("PRAGMA foreign_key_check").fetchall()
                    if broken:
                        raise ValueError(f"{self.path}: {len(broken)} objects without their batch; not migrated")
                conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        finally:
            conn.execute("PRAGMA foreign_keys = ON")

    @contextmanager
    def transaction(self):
        """`with store.transaction() as tx:` one write transaction (BEGIN IMMEDIATE), committed on
        leaving the block, rolled back on any exception. tx.execute / executemany as sqlite3's."""
        conn = self._conn()
        with self._write_lock:
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield _Tx(conn)
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise

    @contextmanager
    def snapshot(self):
        """A read transaction: every query inside sees the same state of the database (a cursor
        reported beside the rows it came with)."""
        conn = self._conn()
        conn.execute("BEGIN")
        try:
            yield conn
        finally:
            conn.execute("COMMIT")

    def snapshot_rows(self, sql: str, args=()) -> list[tuple]:
        """The rows of one read-only query (tokens.py's lookups)."""
        return self._conn().execute(sql, args).fetchall()

    def close(self) -> None:
        with self._registry_lock:
            for conn in self._connections:
                conn.close()
            self._connections.clear()
        self._local = threading.local()

    def journal_mode(self) -> str:
        return self._conn().execute("PRAGMA journal_mode").fetchone()[0]

    # -- writes ----------------------------------------------------------------------------------
    def put(self, batch: FrameBatch, received: float | None = None) -> str:
        """Store one batch and its objects in one transaction. Returns "stored" or "duplicate";
        raises Conflict when the device's batch id holds different content."""
        digest = batch.content_hash()
        received = _time.time() if received is None else received
        with self.transaction() as tx:
            row = tx.execute("SELECT content_sha256 FROM batches WHERE device = ? AND batch_id = ?",
                             (batch.device, batch.batch_id)).fetchone()
            if row is None:
                self._insert(tx, batch, digest, received)
                return "stored"
        if row[0] != digest:
            raise Conflict(f"batch_id {batch.batch_id!r} of device {batch.device!r} is stored already with different "
                           f"content (stored sha256 {row[0][:12]}..., posted {digest[:12]}...)")
        return "duplicate"

    @staticmethod
    def _insert(tx, b: FrameBatch, digest: str, received: float) -> None:
        tx.execute(f"INSERT INTO batches ({_BATCH_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                   (b.device, b.batch_id, b.frame, b.time, b.ego.lat, b.ego.lon, b.ego.alt, b.ego.heading_deg,
                    len(b.objects), digest, received))
        tx.executemany(
            f"INSERT INTO objects ({_OBJECT_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [(b.device, b.batch_id, i, o.cls, o.score, o.lat, o.lon, o.alt, o.depth_m, o.x_m, *o.box, b.time, b.frame)
             for i, o in enumerate(b.objects)])
        tx.execute("INSERT INTO devices VALUES (?, 1, ?) ON CONFLICT (device) DO UPDATE"
                   " SET batches = batches + 1, objects = objects + excluded.objects", (b.device, len(b.objects)))

    def delete(self, device: str | None = None, since: float | None = None, until: float | None = None) -> dict:
        """Delete the batches (and their objects) of `device` (all devices if None) with
        since <= time < until, DELETE_CHUNK batches per transaction so that posts go on meanwhile.
        Returns the counts deleted."""
        where, args = _filters(device, since, until)
        deleted = {"batches": 0, "objects": 0}
        while True:
            with self.transaction() as tx:
                rows = tx.execute(f"SELECT seq, device, batch_id, n_objects FROM batches WHERE {where} LIMIT ?",
                                  (*args, DELETE_CHUNK)).fetchall()
                if not rows:
                    return deleted
                tx.executemany("DELETE FROM objects WHERE device = ? AND batch_id = ?", [r[1:3] for r in rows])
                tx.executemany("DELETE FROM batches WHERE seq = ?", [r[:1] for r in rows])
                per_device: dict[str, list[int]] = {}
                for _, dev, _, n in rows:
                    counts = per_device.setdefault(dev, [0, 0])
                    counts[0] += 1
                    counts[1] += n
                tx.executemany("UPDATE devices SET batches = batches - ?, objects = objects - ? WHERE device = ?",
                               [(b, n, dev) for dev, (b, n) in per_device.items()])
                tx.execute("DELETE FROM devices WHERE batches <= 0")
            deleted["batches"] += len(rows)
            deleted["objects"] += sum(r[3] for r in rows)

    # -- reads -----------------------------------------------------------------------------------
    def objects(self, bbox: tuple[float, float, float, float] | None = None, since: float | None = None,
                limit: int = 5000, after: int | None = None) -> tuple[list[dict], bool, int]:
        """Objects inside bbox = (minlon, minlat, maxlon, maxlat) and at or after `since`, as batch
        dicts in the exchange format (each holding only its matching objects, in posted order).
        Without `after`: the latest `limit` objects, newest first. With `after` (a cursor): the
        objects stored after it, in storage order (the page's "what is new"). A bbox with
        minlon > maxlon crosses the antimeridian (RFC 7946 §5.2). Returns (batches, whether `limit`
        cut the answer, the cursor to pass as `after` next time)."""
        where, args = ["1"], []
        if since is not None:
            where.append("o.time >= ?")
            args.append(since)
        if after is not None:
            where.append("o.id > ?")
            args.append(after)
        if bbox is not None:
            minlon, minlat, maxlon, maxlat = bbox
            where.append("o.lat BETWEEN ? AND ?")
            where.append("o.lon BETWEEN ? AND ?" if minlon <= maxlon else "(o.lon >= ? OR o.lon <= ?)")
            args += [minlat, maxlat, minlon, maxlon]
        order = "o.id" if after is not None else "o.time DESC, o.batch_id, o.idx"
        with self.snapshot() as conn:
            rows = conn.execute(
                "SELECT o.batch_id, o.idx, o.class, o.score, o.box_x1, o.box_y1, o.box_x2, o.box_y2, o.depth_m, o.x_m,"
                " o.lat, o.lon, o.alt, b.device, b.frame, b.time, b.ego_lat, b.ego_lon, b.ego_alt, b.ego_heading_deg, o.id"
                f" FROM objects o JOIN batches b USING (device, batch_id) WHERE {' AND '.join(where)}"
                f" ORDER BY {order} LIMIT ?", (*args, limit + 1)).fetchall()
            newest = conn.execute("SELECT MAX(id) FROM objects").fetchone()[0] or 0
        truncated = len(rows) > limit
        rows = rows[:limit]
        cursor = (rows[-1][20] if truncated else max(newest, after)) if after is not None else newest
        batches: dict[tuple[str, str], dict] = {}
        for r in rows:
            b = batches.get((r[13], r[0]))
            if b is None:
                b = batches[(r[13], r[0])] = {
                    "batch_id": r[0], "device": r[13], "frame": r[14], "time": r[15],
                    "ego": {"lat": r[16], "lon": r[17], "alt": r[18], "heading_deg": r[19]}, "objects": []}
            b["objects"].append({"class": r[2], "score": r[3], "box": list(r[4:8]), "depth_m": r[8], "x_m": r[9],
                                 "lat": r[10], "lon": r[11], "alt": r[12]})
        return list(batches.values()), truncated, cursor

    def tracks(self, since: float | None = None, device: str | None = None, max_points: int = 2000,
               after: int | None = None) -> tuple[dict[str, list[tuple[float, float, float]]], int]:
        """device -> [(time, lon, lat), ...] of its ego positions in time order, and the cursor to
        pass as `after` next time. Without `after`: at most `max_points` per device, spread evenly
        over its time span (first and last kept). With `after`: the positions stored after the
        cursor (at most max_points in all, oldest first; call again with the new cursor for more)."""
        with self.snapshot() as conn:
            newest = conn.execute("SELECT COALESCE(MAX(seq), 0) FROM batches").fetchone()[0]
            if after is not None:
                where, args = _filters(device, since, None)
                rows = conn.execute(f"SELECT seq, device, time, ego_lon, ego_lat FROM batches WHERE {where} AND seq > ?"
                                    " ORDER BY seq LIMIT ?", (*args, after, max_points)).fetchall()
                out: dict[str, list[tuple[float, float, float]]] = {}
                for _, dev, t, lon, lat in rows:
                    out.setdefault(dev, []).append((t, lon, lat))
                cursor = rows[-1][0] if len(rows) == max_points else max(newest, after)
                return {d: sorted(p) for d, p in out.items()}, cursor
            devices = [d for (d,) in conn.execute("SELECT device FROM devices ORDER BY device")
                       if device is None or d == device]
            return {d: p for d in devices if (p := _decimated_track(conn, d, since, max_points))}, newest

    def export(self, device: str | None = None, since: float | None = None, until: float | None = None,
               page: int = 500):
        """Yield the matching batches in the exchange format, in storage order, `page` batches per
        query (no read transaction is held open while the caller streams them out)."""
        where, args = _filters(device, since, until)
        last = 0
        while True:
            with self.snapshot() as conn:
                heads = conn.execute(f"SELECT seq, batch_id, device, frame, time, ego_lat, ego_lon, ego_alt, ego_heading_deg"
                                     f" FROM batches WHERE {where} AND seq > ? ORDER BY seq LIMIT ?",
                                     (*args, last, page)).fetchall()
                objects: dict[tuple[str, str], list[dict]] = {}
                for head in heads:
                    objects[(head[2], head[1])] = [
                        {"class": c, "score": s, "box": [x1, y1, x2, y2], "depth_m": d, "x_m": x, "lat": la, "lon": lo, "alt": al}
                        for c, s, x1, y1, x2, y2, d, x, la, lo, al in conn.execute(
                            "SELECT class, score, box_x1, box_y1, box_x2, box_y2, depth_m, x_m, lat, lon, alt FROM objects"
                            " WHERE device = ? AND batch_id = ? ORDER BY idx", (head[2], head[1]))]
            if not heads:
                return
            for seq, batch_id, dev, frame, t, lat, lon, alt, heading in heads:
                yield {"batch_id": batch_id, "device": dev, "frame": frame, "time": t,
                       "ego": {"lat": lat, "lon": lon, "alt": alt, "heading_deg": heading},
                       "objects": objects[(dev, batch_id)]}
            last = heads[-1][0]

    def counts(self) -> dict:
        """Stored batches, objects and devices: from the per-device counters (a few rows)."""
        devices, batches, objects = self._conn().execute(
            "SELECT COUNT(*), COALESCE(SUM(batches), 0), COALESCE(SUM(objects), 0) FROM devices").fetchone()
        return {"batches": batches, "objects": objects, "devices": devices}


class _Tx:
    """The connection inside Store.transaction(): execute and executemany only (no COMMIT of its own)."""

    def __init__(self, conn: sqlite3.Connection):
        self.execute, self.executemany = conn.execute, conn.executemany

    def executescript_in_tx(self, script: str) -> None:
        # sqlite3's executescript() commits first; statement by statement keeps one transaction
        for statement in script.split(";"):
            if statement.strip():
                self.execute(statement)


def _filters(device: str | None, since: float | None, until: float | None) -> tuple[str, list]:
    where, args = ["1"], []
    for clause, value in (("device = ?", device), ("time >= ?", since), ("time < ?", until)):
        if value is not None:
            where.append(clause)
            args.append(value)
    return " AND ".join(where), args


def _decimated_track(conn: sqlite3.Connection, device: str, since: float | None, max_points: int):
    """A device's positions at or after `since`, at most max_points of them: all when there are
    few; else the first position at or after each of max_points - 1 evenly spaced times (one index
    seek each: the cost does not grow with the track's length), deduplicated, and the last one.
    max_points >= 2."""
    span = conn.execute("SELECT MIN(time), MAX(time), COUNT(*) FROM (SELECT time FROM batches WHERE device = ?"
                        " AND time >= ? ORDER BY time LIMIT ?)", (device, -1e300 if since is None else since,
                                                                  max_points + 1)).fetchone()
    t0, t1, n = span
    if not n:
        return []
    select = "SELECT time, ego_lon, ego_lat FROM batches WHERE device = ? AND time >= ?"
    if n <= max_points:
        return conn.execute(select + " ORDER BY time", (device, t0)).fetchall()
    t1 = conn.execute("SELECT MAX(time) FROM batches WHERE device = ?", (device,)).fetchone()[0]
    rows = conn.execute(
        "WITH RECURSIVE k(i) AS (SELECT 0 UNION ALL SELECT i + 1 FROM k WHERE i < ?)"
        " SELECT DISTINCT (SELECT seq FROM batches WHERE device = ? AND time >= ? + i * ? ORDER BY time LIMIT 1)"
        " FROM k", (max_points - 2, device, t0, (t1 - t0) / (max_points - 1))).fetchall()
    seqs = [s for (s,) in rows if s is not None]
    placeholders = ",".join("?" * len(seqs))
    points = conn.execute(f"SELECT time, ego_lon, ego_lat FROM batches WHERE seq IN ({placeholders}) ORDER BY time",
                          seqs).fetchall()
    last = conn.execute(select + " ORDER BY time DESC LIMIT 1", (device, t1)).fetchone()
    return points if points and points[-1] == last else points + [last]

"""SQLite storage of frame batches and their placed objects (stdlib sqlite3, one file).

Durability: WAL journal with synchronous=FULL (the default), so a batch is on disk (WAL fsynced)
before the service answers 201; the device deletes its queued copy on that answer, so an
acknowledged batch survives a kill and a power loss. The fsync per commit bounds the write rate
(one commit at a time: ~270 batches/s on a disk with a 3.7 ms fsync). synchronous=NORMAL skips it:
still safe against a killed server process (the WAL is in the OS's page cache), but a power loss
or kernel crash may lose the last acknowledged batches. WAL lets readers (the map's GETs) run
beside the writer.

One transaction per batch (BEGIN IMMEDIATE ... COMMIT): a batch and all its objects are stored
together or not at all. Idempotency: `batches.batch_id` is the primary key and `content_sha256`
the hash of the validated batch; a re-post with the same hash is a duplicate (nothing written), a
different hash under the same id is a Conflict.

Threads: FastAPI runs sync endpoints in a thread pool, so every thread gets its own connection
(sqlite3 connections must not be shared across threads mid-statement). Writers go through one
lock: SQLite admits a single writer anyway, and a Python lock queues them fairly instead of
leaving them to SQLite's sleep-and-retry busy handler; busy_timeout still covers other processes
(a load test reading the file, a second server on the same DB).

Objects carry their batch's time and device (denormalised) so the bbox/since query reads one
table through its indexes: (time) for "latest since", (lat, lon) for a small bounding box.
"""

from __future__ import annotations

import sqlite3
import threading
import time as _time
from pathlib import Path

from .schema import FrameBatch

SCHEMA_VERSION = 1
BUSY_TIMEOUT_S = 10.0
SYNCHRONOUS = ("FULL", "NORMAL")  # see the module docstring: power-loss safe, or crash safe and faster

_SCHEMA = """
CREATE TABLE IF NOT EXISTS batches (
    batch_id TEXT PRIMARY KEY,
    device TEXT NOT NULL,
    frame TEXT NOT NULL,
    time REAL NOT NULL,
    ego_lat REAL NOT NULL, ego_lon REAL NOT NULL, ego_alt REAL NOT NULL, ego_heading_deg REAL NOT NULL,
    n_objects INTEGER NOT NULL,
    content_sha256 TEXT NOT NULL,
    received REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS batches_time ON batches (time);
CREATE INDEX IF NOT EXISTS batches_device_time ON batches (device, time);
CREATE TABLE IF NOT EXISTS objects (
    id INTEGER PRIMARY KEY,
    batch_id TEXT NOT NULL REFERENCES batches (batch_id),
    idx INTEGER NOT NULL,
    class TEXT NOT NULL,
    score REAL NOT NULL,
    lat REAL NOT NULL, lon REAL NOT NULL, alt REAL NOT NULL,
    depth_m REAL NOT NULL, x_m REAL NOT NULL,
    box_x1 REAL NOT NULL, box_y1 REAL NOT NULL, box_x2 REAL NOT NULL, box_y2 REAL NOT NULL,
    time REAL NOT NULL,
    device TEXT NOT NULL,
    frame TEXT NOT NULL,
    UNIQUE (batch_id, idx)
);
CREATE INDEX IF NOT EXISTS objects_time ON objects (time);
CREATE INDEX IF NOT EXISTS objects_lat_lon ON objects (lat, lon);
"""


class Conflict(Exception):
    """The batch id is stored already, with different content."""


class Store:
    """The service's database. `put` stores a batch; `objects` and `tracks` read for the map."""

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
        if version not in (0, SCHEMA_VERSION):
            raise ValueError(f"{self.path}: schema version {version}, this service reads version {SCHEMA_VERSION}")
        with self._write_lock:
            conn.executescript(_SCHEMA)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

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
        raises Conflict when the id holds different content."""
        digest = batch.content_hash()
        received = _time.time() if received is None else received
        conn = self._conn()
        with self._write_lock:
            conn.execute("BEGIN IMMEDIATE")
            try:
                row = conn.execute("SELECT content_sha256 FROM batches WHERE batch_id = ?", (batch.batch_id,)).fetchone()
                if row is not None:
                    conn.execute("ROLLBACK")
                    if row[0] != digest:
                        raise Conflict(f"batch_id {batch.batch_id!r} is stored already with different content "
                                       f"(stored sha256 {row[0][:12]}..., posted {digest[:12]}...)")
                    return "duplicate"
                self._insert(conn, batch, digest, received)
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
        return "stored"

    @staticmethod
    def _insert(conn: sqlite3.Connection, b: FrameBatch, digest: str, received: float) -> None:
        conn.execute("INSERT INTO batches VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                     (b.batch_id, b.device, b.frame, b.time, b.ego.lat, b.ego.lon, b.ego.alt, b.ego.heading_deg,
                      len(b.objects), digest, received))
        conn.executemany(
            "INSERT INTO objects (batch_id, idx, class, score, lat, lon, alt, depth_m, x_m,"
            " box_x1, box_y1, box_x2, box_y2, time, device, frame) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [(b.batch_id, i, o.cls, o.score, o.lat, o.lon, o.alt, o.depth_m, o.x_m, *o.box, b.time, b.device, b.frame)
             for i, o in enumerate(b.objects)])

    # -- reads -----------------------------------------------------------------------------------
    def objects(self, bbox: tuple[float, float, float, float] | None = None, since: float | None = None,
                limit: int = 5000) -> tuple[list[dict], bool]:
        """The latest objects (newest first) inside bbox = (minlon, minlat, maxlon, maxlat) and at or
        after `since`, as batch dicts in the exchange format (each holding only its matching objects,
        in their posted order). A bbox with minlon > maxlon crosses the antimeridian (RFC 7946 §5.2).
        Also returns whether `limit` cut the answer short."""
        where, args = ["1"], []
        if since is not None:
            where.append("o.time >= ?")
            args.append(since)
        if bbox is not None:
            minlon, minlat, maxlon, maxlat = bbox
            where.append("o.lat BETWEEN ? AND ?")
            where.append("o.lon BETWEEN ? AND ?" if minlon <= maxlon else "(o.lon >= ? OR o.lon <= ?)")
            args += [minlat, maxlat, minlon, maxlon]
        rows = self._conn().execute(
            "SELECT o.batch_id, o.idx, o.class, o.score, o.box_x1, o.box_y1, o.box_x2, o.box_y2, o.depth_m, o.x_m,"
            " o.lat, o.lon, o.alt, b.device, b.frame, b.time, b.ego_lat, b.ego_lon, b.ego_alt, b.ego_heading_deg"
            f" FROM objects o JOIN batches b USING (batch_id) WHERE {' AND '.join(where)}"
            " ORDER BY o.time DESC, o.batch_id, o.idx LIMIT ?", (*args, limit + 1)).fetchall()
        truncated = len(rows) > limit
        batches: dict[str, dict] = {}
        for r in rows[:limit]:
            b = batches.get(r[0])
            if b is None:
                b = batches[r[0]] = {"batch_id": r[0], "device": r[13], "frame": r[14], "time": r[15],
                                     "ego": {"lat": r[16], "lon": r[17], "alt": r[18], "heading_deg": r[19]},
                                     "objects": []}
            b["objects"].append({"class": r[2], "score": r[3], "box": list(r[4:8]), "depth_m": r[8], "x_m": r[9],
                                 "lat": r[10], "lon": r[11], "alt": r[12]})
        return list(batches.values()), truncated

    def tracks(self, since: float | None = None, device: str | None = None) -> dict[str, list[tuple[float, float, float]]]:
        """device -> [(time, lon, lat), ...] of its ego positions in time order."""
        where, args = ["1"], []
        if since is not None:
            where.append("time >= ?")
            args.append(since)
        if device is not None:
            where.append("device = ?")
            args.append(device)
        out: dict[str, list[tuple[float, float, float]]] = {}
        for dev, t, lon, lat in self._conn().execute(
                f"SELECT device, time, ego_lon, ego_lat FROM batches WHERE {' AND '.join(where)} ORDER BY device, time",
                args):
            out.setdefault(dev, []).append((t, lon, lat))
        return out

    def counts(self) -> dict:
        conn = self._conn()
        return {"batches": conn.execute("SELECT COUNT(*) FROM batches").fetchone()[0],
                "objects": conn.execute("SELECT COUNT(*) FROM objects").fetchone()[0],
                "devices": conn.execute("SELECT COUNT(DISTINCT device) FROM batches").fetchone()[0]}

"""The map service's storage, the part that is the same SQL on every backend: storing a batch with
its idempotency check, retention deletes in chunks, the map's reads and cursors, the export and the
per-device counts. The backends (store.py: SQLite, the embedded default; pg_store.py: PostgreSQL)
give it connections and transactions; their SQL differs only in the table definitions
(`tables_sql`), which are written once here with each backend's column types filled in.

What every backend guarantees (docs/edge-and-map-service.md, "Map service"):
- one transaction per batch: a batch and all its objects are stored together or not at all;
- idempotency: a batch is keyed by (device, batch_id), so a batch id lives in its device's
  namespace; `content_sha256` is the hash of the validated batch: a re-post with the same hash is
  a duplicate (nothing written), a different hash under the same key is a Conflict;
- batches and objects have ids that never go back (not even after a delete), and a read that
  answers with a cursor (`cursor_snapshot`) never sees id N+1 committed while N is still to come:
  the map page's cursors ("what is new since id N") rely on it;
- per-device counts kept in the same transaction as each insert or delete, so /health reads a few
  rows, not a count over millions;
- objects carry their batch's time and device (denormalised) so the bbox/since query reads one
  table through its indexes: (time) for "latest since", (lat, lon) for a small bounding box.

A backend provides `transaction()` (one write transaction: tx.execute / tx.executemany with `?`
placeholders, the cursor's fetchone / fetchall / rowcount), `snapshot()` (a read transaction
that sees one state of the database), `cursor_snapshot()` where writers run side by side (the
reads that page or answer by id: objects, tracks, export), snapshot_rows, close, journal_mode and
`name` (the database as the operator named it, without a password).
"""

from __future__ import annotations

import time as _time

from .schema import FrameBatch

# FULL: a batch is durable (on disk) before its 201; NORMAL: durable against a killed server only,
# faster (each backend's docstring says what it turns off)
SYNCHRONOUS = ("FULL", "NORMAL")
DELETE_CHUNK = 500  # batches per delete transaction: a retention sweep never holds the writer for long

# {id}: an id column that never goes back; {real}: a float that round-trips a Python float exactly;
# {text}: text that sorts byte by byte (the same order on every backend); {count}: a 64-bit integer
_TABLES = """
CREATE TABLE IF NOT EXISTS batches (
    seq {id},
    device {text} NOT NULL,
    batch_id {text} NOT NULL,
    frame {text} NOT NULL,
    time {real} NOT NULL,
    ego_lat {real} NOT NULL, ego_lon {real} NOT NULL, ego_alt {real} NOT NULL, ego_heading_deg {real} NOT NULL,
    n_objects INTEGER NOT NULL,
    content_sha256 {text} NOT NULL,
    received {real} NOT NULL,
    UNIQUE (device, batch_id)
);
CREATE TABLE IF NOT EXISTS objects (
    id {id},
    device {text} NOT NULL,
    batch_id {text} NOT NULL,
    idx INTEGER NOT NULL,
    class {text} NOT NULL,
    score {real} NOT NULL,
    lat {real} NOT NULL, lon {real} NOT NULL, alt {real} NOT NULL,
    depth_m {real} NOT NULL, x_m {real} NOT NULL,
    box_x1 {real} NOT NULL, box_y1 {real} NOT NULL, box_x2 {real} NOT NULL, box_y2 {real} NOT NULL,
    time {real} NOT NULL,
    frame {text} NOT NULL,
    UNIQUE (device, batch_id, idx),
    FOREIGN KEY (device, batch_id) REFERENCES batches (device, batch_id)
);
CREATE TABLE IF NOT EXISTS devices (
    device {text} PRIMARY KEY,
    batches {count} NOT NULL,
    objects {count} NOT NULL
);
CREATE TABLE IF NOT EXISTS tokens (
    id {text} PRIMARY KEY,
    sha256 {text} NOT NULL,
    role {text} NOT NULL CHECK (role IN ('device', 'read', 'admin')),
    device {text} CHECK ((role = 'device') = (device IS NOT NULL)),
    created {real} NOT NULL,
    revoked {real}
);
"""
INDEXES = """
CREATE INDEX IF NOT EXISTS batches_time ON batches (time);
CREATE INDEX IF NOT EXISTS batches_device_time ON batches (device, time);
CREATE INDEX IF NOT EXISTS objects_time ON objects (time);
CREATE INDEX IF NOT EXISTS objects_lat_lon ON objects (lat, lon);
"""
BATCH_COLUMNS = ("device, batch_id, frame, time, ego_lat, ego_lon, ego_alt, ego_heading_deg, n_objects, "
                 "content_sha256, received")
OBJECT_COLUMNS = ("device, batch_id, idx, class, score, lat, lon, alt, depth_m, x_m, box_x1, box_y1, box_x2, "
                  "box_y2, time, frame")


def tables_sql(id: str, real: str, text: str, count: str) -> str:
    """The CREATE TABLE statements with a backend's column types (the placeholders above)."""
    return _TABLES.format(id=id, real=real, text=text, count=count)


def sql_statements(script: str) -> list[str]:
    """A script of ;-separated statements (ours hold no ; in a literal) as single statements: the
    drivers run one at a time, and inside the caller's transaction."""
    return [s for s in script.split(";") if s.strip()]


class Conflict(Exception):
    """The (device, batch id) is stored already, with different content."""


class SqlStore:
    """The service's database. `put` stores a batch; `objects`, `tracks` and `export` read for the
    map and the operator; `delete` removes by device and time range; `counts` for /health."""

    kind = "sql"
    name = ""
    synchronous = "FULL"

    def transaction(self, key: tuple[str, str] | None = None):
        """One write transaction; `key` (device, batch_id): no other transaction of that key runs
        at the same time (put's check-then-insert)."""
        raise NotImplementedError

    def snapshot(self):
        raise NotImplementedError

    def cursor_snapshot(self):
        """A read transaction whose rows and cursor leave no id behind that a writer still holds
        (objects and tracks answer with a cursor). A backend with one writer at a time: snapshot."""
        return self.snapshot()

    # -- writes ----------------------------------------------------------------------------------
    def put(self, batch: FrameBatch, received: float | None = None) -> str:
        """Store one batch and its objects in one transaction. Returns "stored" or "duplicate";
        raises Conflict when the device's batch id holds different content."""
        digest = batch.content_hash()
        received = _time.time() if received is None else received
        with self.transaction(key=(batch.device, batch.batch_id)) as tx:
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
        tx.execute(f"INSERT INTO batches ({BATCH_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                   (b.device, b.batch_id, b.frame, b.time, b.ego.lat, b.ego.lon, b.ego.alt, b.ego.heading_deg,
                    len(b.objects), digest, received))
        tx.executemany(
            f"INSERT INTO objects ({OBJECT_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [(b.device, b.batch_id, i, o.cls, o.score, o.lat, o.lon, o.alt, o.depth_m, o.x_m, *o.box, b.time, b.frame)
             for i, o in enumerate(b.objects)])
        tx.execute("INSERT INTO devices VALUES (?, 1, ?) ON CONFLICT (device) DO UPDATE"
                   " SET batches = devices.batches + 1, objects = devices.objects + excluded.objects", (b.device, len(b.objects)))

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
        where, args = ["TRUE"], []
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
        with self.cursor_snapshot() as conn:
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
        with self.cursor_snapshot() as conn:
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
            with self.cursor_snapshot() as conn:
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
        with self.snapshot() as conn:
            devices, batches, objects = conn.execute(
            "SELECT COUNT(*), CAST(COALESCE(SUM(batches), 0) AS BIGINT), CAST(COALESCE(SUM(objects), 0) AS BIGINT)"
            " FROM devices").fetchone()
        return {"batches": batches, "objects": objects, "devices": devices}


def _filters(device: str | None, since: float | None, until: float | None) -> tuple[str, list]:
    where, args = ["TRUE"], []
    for clause, value in (("device = ?", device), ("time >= ?", since), ("time < ?", until)):
        if value is not None:
            where.append(clause)
            args.append(value)
    return " AND ".join(where), args


def _decimated_track(conn, device: str, since: float | None, max_points: int):
    """A device's positions at or after `since`, at most max_points of them: all when there are
    few; else the first position at or after each of max_points - 1 evenly spaced times (one index
    seek each: the cost does not grow with the track's length), deduplicated, and the last one.
    max_points >= 2."""
    span = conn.execute("SELECT MIN(time), MAX(time), COUNT(*) FROM (SELECT time FROM batches WHERE device = ?"
                        " AND time >= ? ORDER BY time LIMIT ?) AS first_ones", (device, -1e300 if since is None else since,
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

"""SQLite storage of frame batches and their placed objects (stdlib sqlite3, one file): the
embedded default of the map service. The SQL it shares with PostgreSQL (pg_store.py), and the
guarantees both keep, are in sql_store.py; `open_store` picks the backend from --db.

Durability: WAL journal with synchronous=FULL (the default), so a batch is on disk (WAL fsynced)
before the service answers 201; the device deletes its queued copy on that answer, so an
acknowledged batch survives a kill and a power loss. The fsync per commit bounds the write rate
(one commit at a time; the rate: docs/edge-and-map-service.md, re-measured by `python -m
dsfec_jax.edge.loadtest`). synchronous=NORMAL skips it:
still safe against a killed server process (the WAL is in the OS's page cache), but a power loss
or kernel crash may lose the last acknowledged batches. WAL lets readers (the map's GETs) run
beside the writer.

One transaction per batch (BEGIN IMMEDIATE ... COMMIT). SQLite admits one writer per file, so
the ids are taken and committed in order (the cursors' guarantee) without more.

Threads: FastAPI runs sync endpoints in a thread pool, so every thread gets its own connection
(sqlite3 connections must not be shared across threads mid-statement). Writers go through one
lock: SQLite admits a single writer anyway, and a Python lock queues them fairly instead of
leaving them to SQLite's sleep-and-retry busy handler; busy_timeout still covers other processes
(a load test reading the file, a second server on the same DB, `dsfec serve token add`). For the
same reason the server runs one worker process on SQLite: more processes would only queue on the
file's one write lock through that sleep-and-retry handler (server.py).

AUTOINCREMENT ids never go back, not even after a delete. `tokens` holds the sha256 of each
access token (tokens.py), never a token.

Schema version 2 (version 1 keyed batches by batch_id alone and had no devices/tokens tables): an
older database is migrated in one transaction on open, keeping every row.
"""

from __future__ import annotations

import sqlite3
import threading
from contextlib import contextmanager
from pathlib import Path

from .sql_store import (BATCH_COLUMNS, INDEXES, OBJECT_COLUMNS, SYNCHRONOUS, Conflict, SqlStore,  # noqa: F401 (re-exported)
                        sql_statements, tables_sql)

SCHEMA_VERSION = 2
BUSY_TIMEOUT_S = 10.0


_TABLES = tables_sql(id="INTEGER PRIMARY KEY AUTOINCREMENT", real="REAL", text="TEXT", count="INTEGER")
_MIGRATE_FROM_1 = f"""
ALTER TABLE objects RENAME TO objects_v1;
ALTER TABLE batches RENAME TO batches_v1;
DROP INDEX IF EXISTS batches_time; DROP INDEX IF EXISTS batches_device_time;
DROP INDEX IF EXISTS objects_time; DROP INDEX IF EXISTS objects_lat_lon;
{_TABLES}
INSERT INTO batches ({BATCH_COLUMNS}) SELECT {BATCH_COLUMNS} FROM batches_v1 ORDER BY received, rowid;
INSERT INTO objects ({OBJECT_COLUMNS}) SELECT {OBJECT_COLUMNS} FROM objects_v1 ORDER BY id;
DROP TABLE objects_v1;
DROP TABLE batches_v1;
"""
_COUNT_DEVICES = "INSERT INTO devices SELECT device, COUNT(*), SUM(n_objects) FROM batches GROUP BY device"


def open_store(db: str | Path, synchronous: str = "FULL") -> SqlStore:
    """The store --db names: a postgresql:// (or postgres://) URL is a PostgreSQL database
    (pg_store.py, the `postgres` extra), anything else a SQLite file (created if missing)."""
    if is_postgres_url(db):
        try:
            from .pg_store import PostgresStore  # psycopg is an optional extra: loaded only when asked for
        except ImportError as e:
            raise ValueError(f"--db postgresql://...: the PostgreSQL driver is not installed ({e}); "
                             "pip install 'dsfec_jax[postgres]'") from e
        return PostgresStore(str(db), synchronous)
    return Store(db, synchronous)


def is_postgres_url(db: str | Path) -> bool:
    return isinstance(db, str) and db.startswith(("postgresql://", "postgres://"))


class Store(SqlStore):
    """The service's database in one SQLite file (SqlStore says what it does)."""

    kind = "sqlite"

    def __init__(self, path: str | Path, synchronous: str = "FULL"):
        if synchronous not in SYNCHRONOUS:
            raise ValueError(f"synchronous={synchronous!r}; expected one of {SYNCHRONOUS}")
        self.path, self.synchronous = Path(path), synchronous
        self.name = str(self.path)
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
                tx.executescript_in_tx(INDEXES)
                if version == 1:
                    conn.execute(_COUNT_DEVICES)
                    broken = conn.execute("PRAGMA foreign_key_check").fetchall()
                    if broken:
                        raise ValueError(f"{self.path}: {len(broken)} objects without their batch; not migrated")
                conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        finally:
            conn.execute("PRAGMA foreign_keys = ON")

    @contextmanager
    def transaction(self, key: tuple[str, str] | None = None):
        """`with store.transaction() as tx:` one write transaction (BEGIN IMMEDIATE), committed on
        leaving the block, rolled back on any exception. tx.execute / executemany as sqlite3's.
        `key` needs nothing here: one writer at a time holds every key."""
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


class _Tx:
    """The connection inside Store.transaction(): execute and executemany only (no COMMIT of its own)."""

    def __init__(self, conn: sqlite3.Connection):
        self.execute, self.executemany = conn.execute, conn.executemany

    def executescript_in_tx(self, script: str) -> None:
        # sqlite3's executescript() commits first; statement by statement keeps one transaction
        for statement in sql_statements(script):
            self.execute(statement)

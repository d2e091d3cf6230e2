"""PostgreSQL storage of the map service (psycopg 3 with psycopg_pool; the `postgres` extra): the
store for a fleet that outgrows one SQLite writer, chosen by `--db postgresql://...`. The queries
and guarantees are sql_store.py's, shared with SQLite; this module adds connections, transactions
and the schema.

Several server processes (and machines) share one database, each with a pool of connections.
Writers run side by side (their commits share the WAL's flushes), which leaves the map's cursors
a problem: a transaction holding id 7 may commit after one holding id 8, and a reader whose
cursor passed 8 would never see 7. So each write transaction holds a shared advisory lock (one
key per schema) until its commit is visible, and a read that answers with a cursor
(cursor_snapshot) takes the same lock exclusively just while it takes its snapshot: no writer is
then in flight, every id taken so far is committed or rolled back, and the snapshot's ids leave no
hole that a later commit could fill. Such a reader waits for the writers in flight (a commit's
time) and holds new ones back for one round trip. A second lock on (device, batch_id) makes put's
check-then-insert atomic for that key; other reads (tokens, counts) take no lock.

Durability: synchronous="FULL" keeps synchronous_commit on (the 201 is sent once the commit is
flushed to disk); "NORMAL" turns it off: faster, safe against a killed service, but a crash of the
PostgreSQL server or the machine may lose the last acknowledged batches.

Reads run in REPEATABLE READ READ ONLY transactions: every query of one answer (the rows and the
cursor beside them) sees the same committed state.

The bbox query uses plain B-tree indexes, as on SQLite: (time) and (lat, lon). The map asks for
the latest objects of a bbox that covers a fleet's area, ordered by time; a spatial (PostGIS GiST)
index would serve small boxes over a large, old history better, but adds an extension and a
server package for a query that the time index answers today. Text columns sort bytewise
(COLLATE "C") so answers come in the same order as from SQLite.

Schema version: the `dsfec_schema` table holds it (SQLite's is PRAGMA user_version); a database
with another version, or with the service's tables but no version, is refused by name. The schema
is created in the connection's current schema (search_path), so several services (or tests) can
share one database in separate schemas.
"""

from __future__ import annotations

from contextlib import contextmanager

import psycopg
from psycopg.conninfo import conninfo_to_dict
from psycopg_pool import ConnectionPool

from .sql_store import INDEXES, SYNCHRONOUS, SqlStore, sql_statements, tables_sql

SCHEMA_VERSION = 2  # the layout of SQLite's version 2 (sql_store.py); PostgreSQL never had a version 1
CONNECT_TIMEOUT_S = 10
POOL_MAX = 8        # connections per server process: writes queue on the lock anyway, reads are short
POOL_WAIT_S = 30.0  # a request waits this long for a free connection before it fails
_TABLES = tables_sql(id="BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY", real="DOUBLE PRECISION",
                     text='TEXT COLLATE "C"', count="BIGINT")
_WRITERS = "hashtext(current_schema())"  # the advisory lock key of the schema's writers (bigint key space)
_KEY_LOCK = "SELECT pg_advisory_xact_lock(hashtext(current_schema() || ?), hashtext(?))"  # the (int, int) key space


class PostgresStore(SqlStore):
    """The service's database in PostgreSQL (SqlStore says what it does)."""

    kind = "postgresql"

    def __init__(self, dsn: str, synchronous: str = "FULL", pool_max: int = POOL_MAX):
        if synchronous not in SYNCHRONOUS:
            raise ValueError(f"synchronous={synchronous!r}; expected one of {SYNCHRONOUS}")
        self.synchronous, self.name = synchronous, redacted(dsn)
        try:
            psycopg.connect(dsn, connect_timeout=CONNECT_TIMEOUT_S).close()  # the server's own words on a bad DSN
        except psycopg.Error as e:
            raise ValueError(f"--db {self.name}: cannot connect to PostgreSQL ({str(e).strip()})") from e
        self._pool = ConnectionPool(dsn, min_size=1, max_size=pool_max, timeout=POOL_WAIT_S, open=False,
                                    kwargs={"autocommit": True, "connect_timeout": CONNECT_TIMEOUT_S},
                                    configure=self._configure, name="dsfec-map")
        self._pool.open(wait=True, timeout=CONNECT_TIMEOUT_S)
        try:
            self._init_schema()
        except BaseException:
            self._pool.close()
            raise

    def _configure(self, conn: psycopg.Connection) -> None:
        conn.execute(f"SET synchronous_commit = {'on' if self.synchronous == 'FULL' else 'off'}")

    def _init_schema(self) -> None:
        # its own lock: server processes (or token commands) starting together create the tables once
        with self._pool.connection() as conn, conn.transaction():
            conn.execute("SELECT pg_advisory_xact_lock(hashtext(current_schema() || ':schema'))")
            tx = _Connection(conn)
            schema = tx.execute("SELECT current_schema()").fetchone()[0]
            if schema is None:
                raise ValueError(f"--db {self.name}: no schema to create the tables in (search_path names none that exists)")
            tables = {t for (t,) in tx.execute("SELECT table_name FROM information_schema.tables WHERE table_schema = ?",
                                               (schema,))}
            if "dsfec_schema" in tables:
                version = tx.execute("SELECT version FROM dsfec_schema").fetchone()[0]
                if version != SCHEMA_VERSION:
                    raise ValueError(f"--db {self.name}: schema version {version}, this service reads version {SCHEMA_VERSION}")
                return
            if tables & {"batches", "objects", "devices", "tokens"}:
                raise ValueError(f"--db {self.name}: schema {schema!r} holds tables {sorted(tables)} but no dsfec_schema "
                                 "version: not a map service database (give an empty schema or database)")
            for statement in sql_statements(_TABLES + INDEXES):
                tx.execute(statement)
            tx.execute("CREATE TABLE dsfec_schema (version INTEGER NOT NULL)")
            tx.execute("INSERT INTO dsfec_schema VALUES (?)", (SCHEMA_VERSION,))

    @contextmanager
    def transaction(self, key: tuple[str, str] | None = None):
        """`with store.transaction() as tx:` one write transaction, committed on leaving the block,
        rolled back on any exception; `key` (device, batch_id): no other transaction of that key
        runs meanwhile. In pipeline mode: statements whose results nobody reads go out together
        (a put costs two round trips: the duplicate check, then the inserts and the commit)."""
        with self._pool.connection() as conn, conn.pipeline() as pipeline, conn.transaction():
            conn.execute(f"SELECT pg_advisory_xact_lock_shared({_WRITERS})")
            tx = _Connection(conn, pipeline)
            if key is not None:
                tx.execute(_KEY_LOCK, key)
            yield tx

    @contextmanager
    def snapshot(self):
        """A read transaction: every query inside sees the same committed state."""
        with self._pool.connection() as conn, conn.transaction():
            conn.execute("SET TRANSACTION ISOLATION LEVEL REPEATABLE READ, READ ONLY")
            yield _Connection(conn)

    @contextmanager
    def cursor_snapshot(self):
        """A read transaction taken while no writer is in flight (the module docstring)."""
        with self._pool.connection() as conn:
            conn.execute(f"SELECT pg_advisory_lock({_WRITERS})")
            try:
                # the snapshot is taken by the transaction's first query: the unlock, still locked
                conn.execute("BEGIN ISOLATION LEVEL REPEATABLE READ, READ ONLY")
                conn.execute(f"SELECT pg_advisory_unlock({_WRITERS})")
            except BaseException:
                conn.execute("SELECT pg_advisory_unlock_all()")
                raise
            try:
                yield _Connection(conn)
            finally:
                conn.execute("COMMIT")

    def snapshot_rows(self, sql: str, args=()) -> list[tuple]:
        """The rows of one read-only query (tokens.py's lookups)."""
        with self._pool.connection() as conn:
            return _Connection(conn).execute(sql, args).fetchall()

    def close(self) -> None:
        self._pool.close()

    def journal_mode(self) -> str:
        return "wal"  # PostgreSQL always writes ahead; /health's field says the same as for SQLite


class _Connection:
    """A psycopg connection that takes sqlite3's `?` placeholders (sql_store's queries hold no `?`
    or `%` of their own) and has executemany."""

    def __init__(self, conn: psycopg.Connection, pipeline: psycopg.Pipeline | None = None):
        self._conn, self._pipeline = conn, pipeline

    def execute(self, sql: str, args=()) -> _Result:
        return _Result(self._conn.execute(sql.replace("?", "%s"), tuple(args)), self._pipeline)

    def executemany(self, sql: str, rows) -> _Result:
        cursor = self._conn.cursor()
        cursor.executemany(sql.replace("?", "%s"), list(rows))
        return _Result(cursor, self._pipeline)


class _Result:
    """A cursor as sqlite3's: fetchone, fetchall, iteration, and a rowcount that is known also in
    pipeline mode (where it waits for the server's answers first)."""

    def __init__(self, cursor: psycopg.Cursor, pipeline: psycopg.Pipeline | None):
        self._cursor, self._pipeline = cursor, pipeline
        self.fetchone, self.fetchall = cursor.fetchone, cursor.fetchall

    def __iter__(self):
        return iter(self._cursor)

    @property
    def rowcount(self) -> int:
        if self._pipeline is not None:
            self._pipeline.sync()
        return self._cursor.rowcount


def redacted(dsn: str) -> str:
    """The DSN without its password (for messages and logs)."""
    try:
        parts = conninfo_to_dict(dsn)
    except psycopg.ProgrammingError as e:
        raise ValueError(f"--db: not a PostgreSQL connection URL ({e})") from e
    user = parts.get("user", "")
    where = parts.get("host", "") + (f":{parts['port']}" if parts.get("port") else "")
    return f"postgresql://{user + '@' if user else ''}{where}/{parts.get('dbname', '')}"

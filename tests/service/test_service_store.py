"""The stores directly, SQLite and PostgreSQL alike (stores.py's `db`): one transaction per batch
(a failure half-way leaves nothing), the exchange format back, tracks decimated evenly, ids that
commit in order under concurrent writers; clear errors for a file or schema that is not the
service's database, and a light service (no jax import)."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import threading

import pytest

from dsfec_jax.core.pg_scratch import scratch_schema
from dsfec_jax.service.schema import FrameBatch
from dsfec_jax.service.sql_store import SqlStore
from dsfec_jax.service.store import Conflict, Store, open_store
from service_helpers import make_batch
from stores import db, postgres_url  # noqa: F401 (pytest fixtures)


def test_a_batch_that_fails_half_way_leaves_nothing(db, monkeypatch):
    store = open_store(db)
    good = FrameBatch.model_validate(make_batch(0, n_objects=3))
    assert store.put(good) == "stored"

    def half(conn, b, digest, received):  # the batch row goes in, then the objects fail
        conn.execute("INSERT INTO batches (device, batch_id, frame, time, ego_lat, ego_lon, ego_alt, ego_heading_deg,"
                     " n_objects, content_sha256, received) VALUES (?, ?, ?, ?, 0, 0, 0, 0, 0, ?, ?)",
                     (b.device, b.batch_id, b.frame, b.time, digest, received))
        raise OSError("disk I/O error (simulated)")

    monkeypatch.setattr(SqlStore, "_insert", staticmethod(half))
    with pytest.raises(OSError, match="simulated"):
        store.put(FrameBatch.model_validate(make_batch(1, n_objects=3)))
    monkeypatch.undo()
    assert store.counts() == {"batches": 1, "objects": 3, "devices": 1}
    assert store.put(FrameBatch.model_validate(make_batch(1, n_objects=3))) == "stored"  # and it can be posted again
    with pytest.raises(Conflict, match="dev-01:000001"):
        store.put(FrameBatch.model_validate(make_batch(1, n_objects=2)))
    store.close()


def test_reads_come_back_in_the_exchange_format(db):
    store = open_store(db)
    posted = make_batch(4, n_objects=2)
    store.put(FrameBatch.model_validate(posted))
    batches, truncated, cursor = store.objects()
    assert batches == [posted] and not truncated and cursor == 2
    assert store.tracks() == ({"dev-01": [(posted["time"], posted["ego"]["lon"], posted["ego"]["lat"])]}, 1)
    assert list(store.export()) == [posted]
    store.close()


def test_a_file_that_is_not_the_service_database_is_named(tmp_path):
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database" * 100)
    with pytest.raises(ValueError, match="junk.sqlite"):
        Store(junk)
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as conn:
        conn.execute("PRAGMA user_version = 7")
    with pytest.raises(ValueError, match="other.sqlite: schema version 7"):
        Store(other)


def test_a_postgres_database_that_is_not_the_services_is_named():
    url = postgres_url()
    with pytest.raises(ValueError, match="--db postgresql://nobody@/.*cannot connect"):
        open_store("postgresql://nobody@/nowhere?host=/nonexistent-socket-folder")
    with scratch_schema(url, "test") as other:
        store = open_store(other)
        with store.transaction() as tx:
            tx.execute("UPDATE dsfec_schema SET version = 7")
        store.close()
        with pytest.raises(ValueError, match="schema version 7, this service reads version 2"):
            open_store(other)
    with scratch_schema(url, "test") as foreign:
        import psycopg

        with psycopg.connect(foreign, autocommit=True) as conn:
            conn.execute("CREATE TABLE batches (id integer)")
        with pytest.raises(ValueError, match="holds tables \\['batches'\\] but no dsfec_schema"):
            open_store(foreign)


def test_servers_starting_together_create_the_tables_once():
    with scratch_schema(postgres_url(), "test") as url:
        failures = []

        def start():
            try:
                open_store(url).close()
            except Exception as e:  # noqa: BLE001 (any failure is the finding)
                failures.append(repr(e))

        threads = [threading.Thread(target=start) for _ in range(6)]
        [t.start() for t in threads]
        [t.join() for t in threads]
        assert not failures


def test_ids_commit_in_order_under_concurrent_writers(db):
    """The map's cursor ("objects after id N") never skips a row: whenever a reader sees object id
    N, every id below N that will ever be stored is visible too, while writers run side by side."""
    store = open_store(db)
    seen_gaps, stop = [], threading.Event()

    def write(device):
        for i in range(25):
            store.put(FrameBatch.model_validate(make_batch(i, device, n_objects=2)))

    def read():
        while not stop.is_set():
            with store.cursor_snapshot() as conn:  # as objects() and tracks() read
                ids = [i for (i,) in conn.execute("SELECT id FROM objects ORDER BY id")]
            if ids and ids != list(range(1, len(ids) + 1)):  # no rollbacks here: ids have no holes
                seen_gaps.append(ids)

    writers = [threading.Thread(target=write, args=(f"d{k}",)) for k in range(4)]
    reader = threading.Thread(target=read)
    reader.start()
    for w in writers:
        w.start()
    for w in writers:
        w.join()
    stop.set()
    reader.join()
    assert store.counts() == {"batches": 100, "objects": 200, "devices": 4}
    assert not seen_gaps, seen_gaps[0]
    store.close()


def test_the_service_starts_light_without_jax():
    """Nothing the server process or the uplink loads pulls in JAX or the project's heavy rooms."""
    heavy = ("jax", "flax", "optax", "onnxruntime", "dsfec_jax.models", "dsfec_jax.data", "dsfec_jax.train")
    code = ("import sys; import dsfec_jax.service.app, dsfec_jax.service.server, dsfec_jax.edge.uplink; "
            f"print(sorted(m for m in {heavy!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[]", out


def _vm_steps(store: Store, read) -> int:
    """SQLite virtual-machine instructions `read()` costs on the calling thread's connection: a
    count of work that does not depend on the machine's speed or load."""
    steps = [0]
    conn = store._conn()
    conn.set_progress_handler(lambda: steps.__setitem__(0, steps[0] + 1), 1)
    try:
        read()
    finally:
        conn.set_progress_handler(None, 1)
    return steps[0]


def test_health_counts_cost_the_same_for_10_and_2000_batches(tmp_path):
    store = Store(tmp_path / "map.sqlite")
    for i in range(10):
        store.put(FrameBatch.model_validate(make_batch(i, f"d{i % 3}", n_objects=3)))
    small = _vm_steps(store, store.counts)
    with store.transaction() as tx:  # 1990 more batches, the way Store.put books them
        for i in range(10, 2000):
            Store._insert(tx, FrameBatch.model_validate(make_batch(i, f"d{i % 3}", n_objects=3)), "0" * 64, 0.0)
    assert store.counts() == {"batches": 2000, "objects": 6000, "devices": 3}
    assert _vm_steps(store, store.counts) == small < 200  # a COUNT(*) over objects would be >= 6000
    store.close()


def test_tracks_are_decimated_evenly_keeping_the_first_and_last_position(db):
    store = open_store(db)
    n = 3000 if store.kind == "sqlite" else 600  # fewer on PostgreSQL: a round trip per row
    with store.transaction() as tx:
        for i in range(n):
            SqlStore._insert(tx, FrameBatch.model_validate(make_batch(i, n_objects=0)), "0" * 64, 0.0)
    tracks, cursor = store.tracks(max_points=100)
    times = [t for t, _, _ in tracks["dev-01"]]
    assert len(times) == 100 and cursor == n
    assert times[0] == make_batch(0)["time"] and times[-1] == make_batch(n - 1)["time"]
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert max(gaps) < 1.1 * min(gaps) + 0.11  # evenly spread: every ~n/100th frame
    recent, _ = store.tracks(after=n - 10)
    assert [len(p) for p in recent.values()] == [10]
    if store.kind != "sqlite":  # the cost below is counted in SQLite's virtual-machine steps
        return store.close()
    seeks = _vm_steps(store, lambda: store.tracks(max_points=100))
    with store.transaction() as tx:
        for i in range(3000, 9000):
            Store._insert(tx, FrameBatch.model_validate(make_batch(i, n_objects=0)), "0" * 64, 0.0)
    assert _vm_steps(store, lambda: store.tracks(max_points=100)) < 1.5 * seeks  # 3x the rows, not 3x the work
    store.close()

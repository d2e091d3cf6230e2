"""Several server processes on PostgreSQL (server.py): `--workers` is refused by name on SQLite,
and on PostgreSQL the workers share the port, store every batch once, and exit when their
supervisor is SIGKILLed (none is left holding the port)."""

from __future__ import annotations

import os
import signal
import socket
import threading
import time
from pathlib import Path

import pytest

from dsfec_jax.core.pg_scratch import scratch_schema
from dsfec_jax.edge import loadtest
from dsfec_jax.service import tokens
from dsfec_jax.service.server import check_workers
from dsfec_jax.service.store import open_store
from service_helpers import get, make_batch, post, stored_rows
from stores import postgres_url


def test_workers_are_refused_on_sqlite_and_bounded():
    with pytest.raises(ValueError, match="--workers 2 with the SQLite database map.sqlite"):
        check_workers("map.sqlite", 2)
    for n in (0, 1000):
        with pytest.raises(ValueError, match=f"--workers {n}: expected 1 to"):
            check_workers("postgresql://u@h/db", n)
    check_workers("map.sqlite", 1)


def _session(sid: int) -> list[int]:
    """The pids of the live processes of a session (the supervisor made one: loadtest.start_server)."""
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[3] == str(sid) and fields[0] != "Z":
            pids.append(int(stat.parent.name))
    return pids


def test_two_workers_store_every_batch_once_and_exit_with_their_supervisor(tmp_path):
    with scratch_schema(postgres_url(), "test") as db:
        store = open_store(db)
        token = {d: tokens.issue(store, "device", d)[1] for d in ("dev-a", "dev-b")}
        store.close()
        port = loadtest.free_port()
        url = f"http://127.0.0.1:{port}"
        proc = loadtest.start_server(db, port, tmp_path / "server.log", workers=2)
        try:
            loadtest.wait_healthy(url, proc)
            workers = [p for p in _session(proc.pid) if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()]
            assert len(workers) == 2, (tmp_path / "server.log").read_text()
            assert [post(url, make_batch(0, "dev-a"))[0] for _ in range(4)] == [401] * 4  # every worker checks tokens

            def device(name):
                for i in range(20):
                    assert post(url, make_batch(i, name, n_objects=2), token=token[name])[0] == 201
                    assert post(url, make_batch(i, name, n_objects=2), token=token[name])[0] == 200

            threads = [threading.Thread(target=device, args=(d,)) for d in token]
            [t.start() for t in threads]
            [t.join() for t in threads]
            health = get(url, "/health")[1]
            assert (health["store"], health["batches"], health["objects"]) == ("postgresql", 40, 80)
            assert stored_rows(db, "SELECT COUNT(DISTINCT (device, batch_id)) FROM batches") == [(40,)]

            os.kill(proc.pid, signal.SIGKILL)  # the supervisor only: its workers must not stay behind
            proc.wait()
            deadline = time.monotonic() + 15
            while _session(proc.pid) and time.monotonic() < deadline:
                time.sleep(0.2)
            assert not _session(proc.pid)
            with socket.socket() as s:  # nobody listens on the port: a new server may bind it (as uvicorn does)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind(("127.0.0.1", port))
        finally:
            loadtest.kill_group(proc)

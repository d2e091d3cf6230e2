"""Run the map service with uvicorn (asyncio + h11; endpoints in its thread pool), with the
connection limits a public socket needs:

- a deadline for each request's headers (HEADER_TIMEOUT_S from the connection's start or the end
  of the previous response): uvicorn has none, so a client sending one header byte a second
  (slowloris) would hold its connection forever;
- at most MAX_HEADER_BYTES of headers (h11's incomplete-event limit: 400 past it);
- at most `limit_concurrency` connections + requests in flight (503 past it);
- idle keep-alive connections closed after KEEP_ALIVE_S; the body's own deadline and byte limit
  are guards.BodyGuard's.

Workers: one process on a SQLite database (SQLite admits one writer per file: more processes
would only queue on its lock through a sleep-and-retry busy handler, and each process's readers
compete for the same two cores the writer needs). On PostgreSQL, `workers` processes (uvicorn's
supervisor; it restarts a worker that dies) share the listening socket, so the HTTP, JSON,
validation and authentication work of the requests spreads over the cores; each worker builds
its app from the options the supervisor leaves in the environment (SERVE_ENV), and exits when
its supervisor is gone (a SIGKILLed supervisor must not leave workers holding the port).
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import logging
import os
import signal
import threading
import time
from pathlib import Path

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from uvicorn.supervisors import Multiprocess

from .app import Access, create_app
from .store import is_postgres_url, open_store
from ..core.loopback import LOOPBACK_NAMES, is_loopback

HEADER_TIMEOUT_S = 10.0
MAX_HEADER_BYTES = 16 * 1024
KEEP_ALIVE_S = 5
LIMIT_CONCURRENCY = 256
MAX_WORKERS = 64
SERVE_ENV = "DSFEC_SERVE_WORKER_OPTIONS"  # the supervisor's options for its workers (JSON)
log = logging.getLogger("uvicorn.error")  # uvicorn configures it: our lines share its format


class HeaderDeadlineH11(H11Protocol):
    """uvicorn's h11 protocol, plus a deadline for a request's headers (module docstring)."""

    header_timeout_s = HEADER_TIMEOUT_S

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        self._arm_header_deadline()

    def on_response_complete(self) -> None:
        self._arm_header_deadline()  # before super(): it may start a pipelined request at once
        super().on_response_complete()

    def connection_lost(self, exc) -> None:
        self._disarm_header_deadline()
        super().connection_lost(exc)

    def _arm_header_deadline(self) -> None:
        self._disarm_header_deadline()
        self._header_deadline = asyncio.get_running_loop().call_later(self.header_timeout_s, self._header_timeout)

    def _disarm_header_deadline(self) -> None:
        handle = getattr(self, "_header_deadline", None)
        if handle is not None:
            handle.cancel()
            self._header_deadline = None

    def _header_timeout(self) -> None:
        # IDLE: no complete request head since the deadline was armed (a request in progress has
        # moved their_state on, and its body has BodyGuard's deadline)
        if self.conn.their_state is h11.IDLE and not self.transport.is_closing():
            self.transport.close()


def resolve_access(host: str, no_auth: bool = False, reads: str = "auto", allowed_hosts=(), docs: bool = False,
                   retention_days: float | None = None) -> Access:
    """The Access for a server bound to `host`: write auth unless no_auth (refused off loopback),
    reads open on a loopback bind only unless reads="open" / "token" says otherwise."""
    loopback = is_loopback(host)
    if no_auth and not loopback:
        raise ValueError(f"--no-auth with --host {host}: anyone on the network could post as any device; "
                         "--no-auth is for a loopback bind (127.0.0.1) only")
    if reads not in ("auto", "open", "token"):
        raise ValueError(f"reads={reads!r}; expected auto, open or token")
    if retention_days is not None and not retention_days > 0:
        raise ValueError(f"--retention-days {retention_days}: expected a positive number of days")
    bound = () if host in ("0.0.0.0", "::", "") else (host,)
    return Access(write_auth=not no_auth, open_reads=reads == "open" or (reads == "auto" and loopback),
                  allowed_hosts=(*LOOPBACK_NAMES, *bound, *allowed_hosts), docs=docs, retention_days=retention_days)


def serve(db_path: str | Path, host: str = "127.0.0.1", port: int = 8000, log_level: str = "info",
          synchronous: str = "FULL", access: Access | None = None, access_log: bool = True,
          ssl_keyfile: str | None = None, ssl_certfile: str | None = None, workers: int = 1) -> None:
    """Serve the database at `db_path` (a SQLite file or a postgresql:// URL) on host:port until
    interrupted (SIGINT/SIGTERM: graceful). synchronous="FULL" acknowledges a batch once it is on
    disk; "NORMAL" is faster, safe against a killed server but not against a power loss (store.py,
    pg_store.py). TLS when ssl_keyfile and ssl_certfile are given. `workers` > 1: PostgreSQL only."""
    access = resolve_access(host) if access is None else access
    check_workers(db_path, workers)
    if not is_loopback(host) and not ssl_certfile:
        log.warning("listening on %s without TLS: tokens and data cross the network in clear text "
                    "(use --ssl-certfile/--ssl-keyfile or a TLS reverse proxy)", host)
    options = dict(log_level=log_level, access_log=access_log, ssl_keyfile=ssl_keyfile, ssl_certfile=ssl_certfile)
    if workers == 1:
        uvicorn.Server(guarded_config(create_app(db_path, synchronous, access), host, port, **options)).run()
        return
    open_store(db_path, synchronous).close()  # a bad --db fails here, once, by name (and the schema is made)
    os.environ[SERVE_ENV] = json.dumps({"db": str(db_path), "synchronous": synchronous, "parent": os.getpid(),
                                        "access": dataclasses.asdict(access)})
    config = guarded_config(f"{__name__}:app_from_environment", host, port, factory=True, workers=workers, **options)
    Multiprocess(config, sockets=[config.bind_socket()]).run()


def check_workers(db_path: str | Path, workers: int) -> None:
    if not 1 <= workers <= MAX_WORKERS:
        raise ValueError(f"--workers {workers}: expected 1 to {MAX_WORKERS}")
    if workers > 1 and not is_postgres_url(db_path):
        raise ValueError(f"--workers {workers} with the SQLite database {db_path}: SQLite takes one writer at a time, "
                         "so the service runs one process on it; several workers need a postgresql:// --db")


def app_from_environment():
    """A worker's app (uvicorn's factory), from the options its supervisor left in SERVE_ENV."""
    options = json.loads(os.environ[SERVE_ENV])
    access = options["access"]
    access.update({k: tuple(v) for k, v in access.items() if isinstance(v, list)})
    threading.Thread(target=_exit_with_parent, args=(options["parent"],), daemon=True).start()
    return create_app(options["db"], options["synchronous"], Access(**access))


def _exit_with_parent(parent: int, every_s: float = 1.0) -> None:
    while os.getppid() == parent:
        time.sleep(every_s)
    log.warning("the supervisor (pid %s) is gone: this worker stops", parent)
    os.kill(os.getpid(), signal.SIGTERM)  # uvicorn's graceful shutdown


def guarded_config(app, host: str, port: int, header_timeout_s: float = HEADER_TIMEOUT_S, **options) -> uvicorn.Config:
    """uvicorn's Config for `app` with the connection limits of the module docstring."""
    # the class itself by default: workers get the config pickled, and a class made here is not importable
    protocol = HeaderDeadlineH11 if header_timeout_s == HEADER_TIMEOUT_S else \
        type("HeaderDeadlineH11", (HeaderDeadlineH11,), {"header_timeout_s": header_timeout_s})
    return uvicorn.Config(app, host=host, port=port, http=protocol,
                          h11_max_incomplete_event_size=MAX_HEADER_BYTES, limit_concurrency=LIMIT_CONCURRENCY,
                          timeout_keep_alive=KEEP_ALIVE_S, **options)

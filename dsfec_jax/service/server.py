"""Run the map service with uvicorn (one process, asyncio + h11; endpoints in its thread pool),
with the connection limits a public socket needs:

- a deadline for each request's headers (HEADER_TIMEOUT_S from the connection's start or the end
  of the previous response): uvicorn has none, so a client sending one header byte a second
  (slowloris) would hold its connection forever;
- at most MAX_HEADER_BYTES of headers (h11's incomplete-event limit: 400 past it);
- at most `limit_concurrency` connections + requests in flight (503 past it);
- idle keep-alive connections closed after KEEP_ALIVE_S; the body's own deadline and byte limit
  are guards.BodyGuard's.
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from .app import Access, create_app
from ..core.loopback import LOOPBACK_NAMES, is_loopback

HEADER_TIMEOUT_S = 10.0
MAX_HEADER_BYTES = 16 * 1024
KEEP_ALIVE_S = 5
LIMIT_CONCURRENCY = 256
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
          ssl_keyfile: str | None = None, ssl_certfile: str | None = None) -> None:
    """Serve the database at `db_path` on host:port until interrupted (SIGINT/SIGTERM: graceful).
    synchronous="FULL" acknowledges a batch once fsynced; "NORMAL" is faster, safe against a killed
    server but not against a power loss (store.py). TLS when ssl_keyfile and ssl_certfile are given."""
    access = resolve_access(host) if access is None else access
    if not is_loopback(host) and not ssl_certfile:
        log.warning("listening on %s without TLS: tokens and data cross the network in clear text "
                    "(use --ssl-certfile/--ssl-keyfile or a TLS reverse proxy)", host)
    app = create_app(db_path, synchronous, access)
    uvicorn.Server(guarded_config(app, host, port, log_level=log_level, access_log=access_log,
                                  ssl_keyfile=ssl_keyfile, ssl_certfile=ssl_certfile)).run()


def guarded_config(app, host: str, port: int, header_timeout_s: float = HEADER_TIMEOUT_S, **options) -> uvicorn.Config:
    """uvicorn's Config for `app` with the connection limits of the module docstring."""
    protocol = type("HeaderDeadlineH11", (HeaderDeadlineH11,), {"header_timeout_s": header_timeout_s})
    return uvicorn.Config(app, host=host, port=port, http=protocol,
                          h11_max_incomplete_event_size=MAX_HEADER_BYTES, limit_concurrency=LIMIT_CONCURRENCY,
                          timeout_keep_alive=KEEP_ALIVE_S, **options)

"""The edge device's link to the map service: a disk spool (edge.spool) drained by a sender thread.

`send(batch)` writes the batch into the spool durably (its own file, fsynced, and the folder
fsynced: core/atomic.py), hands it to the sender thread and returns: it does no network I/O, so a
frame loop never waits for the server, whatever the backlog. The sender posts the queued files
oldest first; a crash or a power loss at any point loses nothing, and a new Uplink on the same
folder resumes the leftover files. `flush(deadline_s)` waits for the queue to empty.

What each answer does to the queued file:
  201 stored, 200 duplicate    delivered: the file is removed. A duplicate is a retry whose first
                               attempt reached the database but whose answer was lost. The answer
                               must name the batch id (the map service's does): a 200 from
                               something else would otherwise swallow every batch.
  409 conflict                 the id is stored with other content: retrying cannot help; the file
                               moves to conflicts/ with the server's reason beside it.
  422, 413                     a bad or oversized batch: moved to rejected/ with the reason.
  network error, 5xx,          kept for a retry; the next attempt waits an exponential backoff
  408, 425, 429                (backoff_s doubling to max_backoff_s, with jitter so that a fleet
                               does not return in lockstep after an outage).
  anything else: 401, 403,     fatal: a wrong URL, token or proxy, which would refuse every batch
  404, 405, 400, 3xx, ...      alike. The sender stops (the file stays queued, nothing is set
                               aside), `fatal` says what the server answered and what to check,
                               and flush() returns False at once.
Delivery stops at the first retryable failure: batches stay in order and a down server costs one
connection attempt per backoff period, not one per queued file.

HTTP: stdlib http.client over one kept-alive connection (a device posting 10 frames/s should not
pay a TCP (and TLS) handshake per frame). A request on a kept-alive connection that the server had
closed is retried once at once on a new one; that is safe because a batch id is idempotent at the
server. `token`: sent as `Authorization: Bearer <token>`. Environment proxies are not used.
"""

from __future__ import annotations

import json
import logging
import random
import re
import threading
import time
import urllib.parse
from http.client import HTTPConnection, HTTPException, HTTPSConnection
from pathlib import Path
from typing import Callable

from ..core.loopback import is_loopback
from .spool import Spool, SpoolFull, batch_id_of

__all__ = ["Uplink", "SpoolFull"]

log = logging.getLogger(__name__)

SET_ASIDE = {409: "conflicts", 413: "rejected", 422: "rejected"}
RETRYABLE_4XX = (408, 425, 429)
FATAL_HINTS = {
    400: "refused before the map service read it (a Host check or a proxy?); the service answers a bad batch with 422",
    401: "no valid token: give --token-file PATH or DSFEC_MAP_TOKEN (a device token from the map service)",
    403: "the token may not write this batch (is --device the token's device?)",
    404: "no map service at this URL (--server is the service's base URL, without /detections)",
    405: "this URL does not take POST /detections (--server is the service's base URL)",
    407: "a proxy on the way wants authentication",
}
_TOKEN = re.compile(r"^[A-Za-z0-9\-._~+/]+=*$")  # RFC 6750's b64token: nothing that could break the header
WARN_AT = 0.8  # of the spool's cap


def check_token(token: str) -> str:
    if not isinstance(token, str) or not 0 < len(token) <= 4096 or not _TOKEN.match(token):
        raise ValueError("token: expected 1-4096 characters of letters, digits and -._~+/ (then '='s), "
                         "as a bearer token is (RFC 6750); the token itself is not shown")
    return token


class _KeepAlive:
    """One persistent HTTP/1.1 connection to the server, reopened after any failure."""

    def __init__(self, server_url: str, timeout_s: float, token: str | None):
        parts = urllib.parse.urlsplit(server_url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"server_url: expected http://host[:port] or https://..., got {server_url!r}")
        self.kind = HTTPSConnection if parts.scheme == "https" else HTTPConnection
        self.host, self.port, self.timeout_s = parts.hostname, parts.port, timeout_s
        self.path = parts.path.rstrip("/") + "/detections"
        self.url = f"{parts.scheme}://{parts.netloc}{self.path}"
        self.headers = {"Content-Type": "application/json"}
        if token is not None:
            self.headers["Authorization"] = f"Bearer {check_token(token)}"
            if parts.scheme == "http" and not is_loopback(parts.hostname):
                log.warning("sending a bearer token over plain http to %s: anyone on the way can read it "
                            "(put the map service behind TLS and use https://)", parts.hostname)
        self.conn = None

    def post(self, body: bytes) -> tuple[int, str, str | None]:
        """-> (status, body text, Location header)."""
        while True:
            fresh = self.conn is None
            if fresh:
                self.conn = self.kind(self.host, self.port, timeout=self.timeout_s)
            try:
                self.conn.request("POST", self.path, body, self.headers)
                reply = self.conn.getresponse()
                text = reply.read(1 << 16).decode("utf-8", "replace")  # an answer is small: read a bounded prefix
                if not reply.isclosed():
                    self.close()  # a longer body than that is not the map service's: do not read on
            except (OSError, HTTPException) as e:
                self.close()
                if fresh or isinstance(e, TimeoutError):  # a timeout is the server's slowness, not a stale socket
                    raise
                continue
            if reply.will_close:
                self.close()
            return reply.status, text, reply.getheader("Location")

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None


def _plain(value):
    if hasattr(value, "item") and callable(value.item):
        return value.item()
    raise TypeError(f"frame batch: {type(value).__name__} {value!r} is not JSON")


def encode(batch: dict) -> tuple[str, bytes]:
    """-> (batch id, JSON body); NaN is no JSON: refused here, in the device's code, not at the server."""
    batch_id = batch.get("batch_id") if isinstance(batch, dict) else None
    if not isinstance(batch_id, str) or not batch_id:
        raise ValueError(f"batch_id: expected a non-empty string in the frame batch, got {batch_id!r}")
    try:  # numpy scalars -> .item()
        return batch_id, json.dumps(batch, allow_nan=False, separators=(",", ":"), default=_plain).encode()
    except ValueError as e:
        raise ValueError(f"frame batch {batch_id}: {e} (a NaN or infinity; JSON has none)") from None


def classify(status: int | None, text: str, batch_id: str) -> str:
    """An answer -> "delivered", "conflicts", "rejected", "retry" or "fatal"."""
    if status in (200, 201):
        try:
            reply = json.loads(text)
        except ValueError:
            return "fatal"
        return "delivered" if isinstance(reply, dict) and reply.get("batch_id") == batch_id else "fatal"
    if status in SET_ASIDE:
        return SET_ASIDE[status]
    if status is None or status >= 500 or status in RETRYABLE_4XX:
        return "retry"
    return "fatal"


def fatal_message(url: str, status: int, text: str, location: str | None) -> str:
    if 300 <= status < 400:
        hint = f"redirected to {location!r}: give the final URL in --server (https://?)"
    elif status in (200, 201):
        hint = "not as the map service answers (no matching batch_id): is --server the map service?"
    else:
        hint = FATAL_HINTS.get(status, "not an answer the map service gives")
    return f"the server at {url} answered HTTP {status}: {hint}. Its answer: {text[:300]!r}"


class Uplink:
    """Queue-and-post of frame batches to `server_url` (e.g. "http://127.0.0.1:8000").

    counts: sent (201), duplicate (200), retried (failed attempts kept for a retry), rejected
    (422/413: in rejected/), conflicts (409: in conflicts/). `fatal`: None, or why the sender
    stopped (a wrong URL, token or proxy). `observer(status, seconds)` (optional) is called from
    the sender thread after every POST attempt with the HTTP status (None for a network error).
    max_queued / max_queued_bytes: the spool's cap (edge.spool): at the cap send() waits up to
    room_wait_s for the sender to make room, then raises SpoolFull and queues nothing (no queued
    batch is ever dropped); a warning is logged when the spool passes 80 % of the cap.
    One Uplink per queue_dir (two on one folder would post the same files twice), and one thread
    calling send().
    """

    def __init__(self, server_url: str, queue_dir: str | Path, timeout_s: float = 5.0, backoff_s: float = 0.25,
                 max_backoff_s: float = 5.0, observer: Callable[[int | None, float], None] | None = None,
                 token: str | None = None, max_queued: int = 100_000, max_queued_bytes: int = 1 << 30,
                 room_wait_s: float = 30.0):
        self._http = _KeepAlive(server_url, timeout_s, token)
        self.url = self._http.url
        self.spool = Spool(queue_dir, max_queued, max_queued_bytes)
        self.queue_dir = self.spool.folder
        removed = self.spool.removed_temporaries
        if removed:
            log.warning("%s: removed %d interrupted queue writes (%s): their frames were never recorded as done",
                        self.queue_dir, len(removed), ", ".join(removed[:3]))
        self.timeout_s, self.backoff_s, self.max_backoff_s = timeout_s, backoff_s, max_backoff_s
        self.observer, self.room_wait_s = observer, room_wait_s
        self.counts = {"sent": 0, "duplicate": 0, "retried": 0, "rejected": 0, "conflicts": 0}
        self.last_error: str | None = None
        self.fatal: str | None = None
        self._failures = 0          # consecutive retryable failures (sets the backoff)
        self._next_try = 0.0        # time.monotonic() before which no attempt is made
        self._rng = random.Random()
        self._cv = threading.Condition()
        self._sender: threading.Thread | None = None
        self._closing = False
        self._warned = False

    # -- the producer's side ---------------------------------------------------------------------
    def send(self, batch: dict, on_spooled: Callable[[dict], None] | None = None) -> int:
        """Queue `batch` durably; then `on_spooled(batch)` (the caller records it as done: it is on
        disk, and not yet posted); then hand it to the sender. Returns the batches queued.
        Raises ValueError for what is not a batch and SpoolFull at the cap (nothing queued)."""
        batch_id, body = encode(batch)
        self._wait_for_room(len(body))
        path, size = self.spool.write(batch_id, body)
        if on_spooled is not None:
            on_spooled(batch)
        with self._cv:
            self.spool.append(path, size)
            self._warn_if_filling()
            self._start()
            self._cv.notify_all()
            return len(self.spool)

    def _wait_for_room(self, size: int) -> None:
        """At the cap, give the sender up to room_wait_s to make room (a server that is back drains
        the backlog fast); then write() refuses the batch."""
        end = time.monotonic() + self.room_wait_s
        with self._cv:
            self._start()
            while not self.spool.has_room(size) and self.fatal is None and (left := end - time.monotonic()) > 0:
                self._cv.wait(left)

    def pending(self) -> list[Path]:
        """The queued batch files, oldest first."""
        with self._cv:
            return self.spool.paths()

    def flush(self, deadline_s: float) -> bool:
        """Wait until the queue is empty (True), or `deadline_s` seconds have passed or a fatal
        answer stopped the sender (False)."""
        end = time.monotonic() + deadline_s
        with self._cv:
            self._start()
            while len(self.spool) and self.fatal is None:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(left)
            return not len(self.spool)

    def close(self) -> None:
        """Stop the sender after its current attempt; what is queued stays on disk."""
        with self._cv:
            self._closing = True
            self._cv.notify_all()
        if self._sender is not None:
            self._sender.join(self.timeout_s + 1.0)
        self._http.close()

    def summary(self) -> dict:
        """counts, what is queued, the set-aside totals of the folder (earlier runs' too), fatal, and
        delivered_all: nothing queued, nothing ever set aside, no fatal answer."""
        set_aside = self.spool.set_aside_count()
        queued = len(self.spool)
        return {**self.counts, "queued": queued, "rejected_total": set_aside["rejected"],
                "conflicts_total": set_aside["conflicts"], "fatal": self.fatal,
                "delivered_all": queued == 0 and not any(set_aside.values()) and self.fatal is None}

    def _warn_if_filling(self) -> None:
        if self.spool.fullness() >= WARN_AT and not self._warned:
            self._warned = True
            log.warning("%s holds %d batches (%.1f MB), %d %% of its cap (%d batches, %.1f MB): the server at %s "
                        "has not taken them (%s); at the cap new batches are refused, none is dropped",
                        self.queue_dir, len(self.spool), self.spool.nbytes / 1e6, round(100 * self.spool.fullness()),
                        self.spool.max_files, self.spool.max_bytes / 1e6, self.url, self.last_error or "no error yet")
        elif self.spool.fullness() < WARN_AT / 2:
            self._warned = False

    # -- the sender thread -----------------------------------------------------------------------
    def _start(self) -> None:
        """Start the sender on first use, not at construction: a caller may first read what a killed
        run left queued (edge.run does) before any of it is posted and removed."""
        if self._sender is None and not self._closing:
            self._sender = threading.Thread(target=self._drain, name=f"uplink {self.queue_dir}", daemon=True)
            self._sender.start()

    def _due_in(self) -> float | None:
        """0 when the oldest batch may be posted now, seconds to wait, or None: wait to be woken."""
        if self.fatal is not None or not len(self.spool):
            return None
        return max(0.0, self._next_try - time.monotonic())

    def _drain(self) -> None:
        while True:
            with self._cv:
                while not self._closing and (wait := self._due_in()) != 0.0:
                    self._cv.wait(wait)
                if self._closing:
                    return
                path = self.spool.oldest()
            try:
                self._post(path)  # the network and file I/O run outside the lock: send() goes on meanwhile
            except Exception as e:  # a full disk, a queued file removed by hand...: stop loudly, not silently
                self.fatal = f"the uplink's sender failed on {path}: {type(e).__name__}: {e}"
                log.exception("%s; the sender stopped, the queue stays on disk", self.fatal)
            with self._cv:
                self._cv.notify_all()

    def _post(self, path: Path) -> None:
        """POST the oldest queued file and act on the answer (see the module's table)."""
        batch_id, body = batch_id_of(path), path.read_bytes()
        start = time.monotonic()
        try:
            status, text, location = self._http.post(body)
        except (OSError, HTTPException) as e:  # refused, reset, timed out, unreachable, garbled
            status, text, location = None, f"{type(e).__name__}: {e}", None
        if self.observer is not None:
            self.observer(status, time.monotonic() - start)
        outcome = classify(status, text, batch_id)
        if outcome == "delivered":
            path.unlink()
            self.counts["sent" if status == 201 else "duplicate"] += 1
            self._failures = 0
        elif outcome in ("conflicts", "rejected"):
            self._set_aside(path, outcome, status, text)
        elif outcome == "retry":
            self._retry_later(status, text)
            return
        else:
            self.fatal = fatal_message(self.url, status, text, location)
            log.error("%s; the sender stopped, %s stays queued", self.fatal, path.name)
            return
        with self._cv:
            self.spool.pop_oldest(path)

    def _set_aside(self, path: Path, folder: str, status: int, text: str) -> None:
        """Move a batch the server will never take out of the queue, with the server's reason."""
        try:
            reason = json.loads(text)
        except ValueError:
            reason = text
        self.spool.set_aside(path, folder, {"status": status, "url": self.url, "reason": reason})
        self.counts[folder] += 1
        self.last_error = f"{path.name}: HTTP {status}: {text[:500]}"

    def _retry_later(self, status: int | None, text: str) -> None:
        self.counts["retried"] += 1
        self.last_error = f"HTTP {status}: {text[:500]}" if status is not None else text
        self._failures += 1
        wait = min(self.max_backoff_s, self.backoff_s * 2 ** (self._failures - 1))
        self._next_try = time.monotonic() + wait * self._rng.uniform(0.5, 1.0)

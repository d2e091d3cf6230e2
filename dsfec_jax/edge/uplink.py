"""The edge device's link to the map service: a disk queue in front of POST /detections.

`send(batch)` first writes the batch into `queue_dir` (one JSON file per batch, atomically:
core/atomic.py), then tries to deliver everything queued, oldest first. So a batch exists on disk
before any network I/O, and a crash or a power loss at any point loses nothing: a new Uplink on
the same `queue_dir` resumes the leftover files.

What each answer does to the queued file:
  201 stored, 200 duplicate    delivered: the file is removed. A duplicate is a retry whose first
                               attempt reached the database but whose answer was lost.
  409 conflict                 the id is stored with other content: retrying cannot help; the file
                               moves to queue_dir/conflicts/ with the server's reason beside it.
  other 4xx (422, 413, ...)    a bad batch: moved to queue_dir/rejected/ with the reason.
  network error, 5xx, 408, 429 kept for a retry; the next attempt waits an exponential backoff
                               (backoff_s doubling to max_backoff_s, with jitter so that a fleet
                               does not return in lockstep after an outage).
Delivery stops at the first retryable failure: batches stay in order and a down server costs one
connection attempt per backoff period, not one per queued file. While backing off, send() only
enqueues, so a frame loop never blocks on a dead server for longer than one `timeout_s`.

Queue file names: "<12-digit sequence>_<batch id, percent-encoded>.json"; the sequence continues
from the largest one found at start, so order survives restarts. Files whose names start with "."
are atomic-write temporaries and are ignored.

HTTP: stdlib http.client over one kept-alive connection (no client dependency; a device posting
10 frames/s should not pay a TCP (and TLS) handshake per frame). A request on a kept-alive
connection that the server had closed is retried once at once on a new one; that is safe because
a batch id is idempotent at the server. Environment proxies are not used.
"""

from __future__ import annotations

import json
import random
import re
import time
import urllib.parse
from http.client import HTTPConnection, HTTPException, HTTPSConnection
from pathlib import Path
from typing import Callable

from ..core.atomic import sync_dir, write_bytes, write_json

_QUEUED = re.compile(r"^(\d{12})_(.+)\.json$")
RETRYABLE_4XX = (408, 429)


class _KeepAlive:
    """One persistent HTTP/1.1 connection to the server, reopened after any failure."""

    def __init__(self, server_url: str, timeout_s: float, token: str | None = None):
        self.headers = {"Content-Type": "application/json", **({"Authorization": f"Bearer {token}"} if token else {})}
        parts = urllib.parse.urlsplit(server_url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"server_url: expected http://host[:port] or https://..., got {server_url!r}")
        self.kind = HTTPSConnection if parts.scheme == "https" else HTTPConnection
        self.host, self.port, self.timeout_s = parts.hostname, parts.port, timeout_s
        self.path = parts.path.rstrip("/") + "/detections"
        self.url = f"{parts.scheme}://{parts.netloc}{self.path}"
        self.conn = None

    def post(self, body: bytes) -> tuple[int, str]:
        while True:
            fresh = self.conn is None
            if fresh:
                self.conn = self.kind(self.host, self.port, timeout=self.timeout_s)
            try:
                self.conn.request("POST", self.path, body, self.headers)
                reply = self.conn.getresponse()
                text = reply.read().decode("utf-8", "replace")
            except (OSError, HTTPException) as e:
                self.close()
                if fresh or isinstance(e, TimeoutError):  # a timeout is the server's slowness, not a stale socket
                    raise
                continue
            if reply.will_close:
                self.close()
            return reply.status, text

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None


def _plain(value):
    if hasattr(value, "item") and callable(value.item):
        return value.item()
    raise TypeError(f"frame batch: {type(value).__name__} {value!r} is not JSON")


class Uplink:
    """Queue-and-post of frame batches to `server_url` (e.g. "http://127.0.0.1:8000").

    counts: sent (201), duplicate (200), retried (failed attempts kept for a retry), rejected
    (4xx: in rejected/), conflicts (409: in conflicts/). `observer(status, seconds)` (optional) is
    called after every POST attempt with the HTTP status (None for a network error) and its time.
    `token`: the device's write token, sent as `Authorization: Bearer <token>`.
    One Uplink per device loop and queue_dir: it is not thread-safe, and two on one folder would
    post the same files twice (harmless at the server, but counted twice).
    """

    def __init__(self, server_url: str, queue_dir: str | Path, timeout_s: float = 5.0, backoff_s: float = 0.25,
                 max_backoff_s: float = 5.0, observer: Callable[[int | None, float], None] | None = None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 token: str | None = None):
        self._http = _KeepAlive(server_url, timeout_s, token)
        self.url = self._http.url
        self.queue_dir = Path(queue_dir)
        self.queue_dir.mkdir(parents=True, exist_ok=True)
        self.timeout_s, self.backoff_s, self.max_backoff_s = timeout_s, backoff_s, max_backoff_s
        self.observer, self.clock, self.sleep = observer, clock, sleep
        self.counts = {"sent": 0, "duplicate": 0, "retried": 0, "rejected": 0, "conflicts": 0}
        self.last_error: str | None = None
        self._failures = 0          # consecutive retryable failures (sets the backoff)
        self._next_try = 0.0        # clock() before which no attempt is made
        self._rng = random.Random()
        self._seq = self._next_sequence()

    def _next_sequence(self) -> int:
        """One past the largest sequence number in the queue and the set-aside folders (a reused
        number could overwrite an earlier rejected batch when it is set aside too)."""
        names = [p.name for d in (self.queue_dir, self.queue_dir / "rejected", self.queue_dir / "conflicts")
                 if d.is_dir() for p in d.iterdir()]
        return max((int(m.group(1)) for m in map(_QUEUED.match, names) if m), default=-1) + 1

    def pending(self) -> list[Path]:
        """The queued batch files, oldest first."""
        return sorted(p for p in self.queue_dir.iterdir() if p.is_file() and _QUEUED.match(p.name))

    def send(self, batch: dict) -> int:
        """Queue `batch` durably, then deliver what the backoff allows. Returns the files still queued."""
        batch_id = batch.get("batch_id") if isinstance(batch, dict) else None
        if not isinstance(batch_id, str) or not batch_id:
            raise ValueError(f"batch_id: expected a non-empty string in the frame batch, got {batch_id!r}")
        try:  # NaN is no JSON: fail here, in the device's code, not at the server; numpy scalars -> .item()
            body = json.dumps(batch, allow_nan=False, separators=(",", ":"), default=_plain).encode()
        except ValueError as e:
            raise ValueError(f"frame batch {batch_id}: {e} (a NaN or infinity; JSON has none)") from None
        write_bytes(self.queue_dir / f"{self._seq:012d}_{urllib.parse.quote(batch_id, safe='')}.json", body)
        self._seq += 1
        return self.deliver()

    def deliver(self) -> int:
        """One pass over the queue, oldest first, unless backing off. Returns the files still queued."""
        queued = self.pending()
        if self.clock() < self._next_try:
            return len(queued)
        for i, path in enumerate(queued):
            if not self._post(path):
                return len(queued) - i
        return 0

    def flush(self, deadline_s: float) -> bool:
        """Retry until the queue is empty (True) or `deadline_s` seconds have passed (False)."""
        end = self.clock() + deadline_s
        while self.deliver():
            now = self.clock()
            if now >= end:
                return False
            self.sleep(max(0.0, min(self._next_try, end) - now) or 0.01)
        return True

    # -- one attempt -----------------------------------------------------------------------------
    def _post(self, path: Path) -> bool:
        """POST one queued file; True when it has left the queue (delivered or set aside)."""
        start = self.clock()
        try:
            status, text = self._http.post(path.read_bytes())
        except (OSError, HTTPException) as e:  # refused, reset, timed out, unreachable, garbled
            status, text = None, f"{type(e).__name__}: {e}"
        if self.observer is not None:
            self.observer(status, self.clock() - start)
        if status in (200, 201):
            self.counts["sent" if status == 201 else "duplicate"] += 1
            path.unlink()
            self._failures = 0
            return True
        if status is not None and 400 <= status < 500 and status not in RETRYABLE_4XX:
            self._set_aside(path, "conflicts" if status == 409 else "rejected", status, text)
            return True
        self._retry_later(status, text)
        return False

    def _set_aside(self, path: Path, folder: str, status: int, text: str) -> None:
        """Move a batch the server will never take out of the queue, with the server's reason."""
        target = self.queue_dir / folder
        target.mkdir(exist_ok=True)
        try:
            reason = json.loads(text)
        except ValueError:
            reason = text
        write_json(target / f"{path.stem}.reason.json", {"status": status, "url": self.url, "reason": reason})
        path.replace(target / path.name)
        sync_dir(self.queue_dir)
        self.counts["conflicts" if status == 409 else "rejected"] += 1
        self.last_error = f"{path.name}: HTTP {status}: {text[:500]}"

    def _retry_later(self, status: int | None, text: str) -> None:
        self.counts["retried"] += 1
        self.last_error = f"HTTP {status}: {text[:500]}" if status is not None else text
        self._failures += 1
        wait = min(self.max_backoff_s, self.backoff_s * 2 ** (self._failures - 1))
        self._next_try = self.clock() + wait * self._rng.uniform(0.5, 1.0)

"""Hostile input against the map service as it ships (write tokens on, Host allow-list, body and
header bounds), over real sockets: malformed and out-of-range batches, oversized, chunked and
lying bodies, slow clients, squatting without a token or with another device's, a foreign Host.
Each gets a 4xx or a closed connection, nothing bad is stored (the database is read at the end),
and /health keeps answering meanwhile. One server for the module (short deadlines so it is fast),
on each store (stores.py's `module_db`)."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path

import pytest

from dsfec_jax.service import tokens
from dsfec_jax.service.app import Access
from dsfec_jax.service.store import open_store
from service_helpers import LAT0, LiveServer, changed, get, make_batch, post, stored_rows
from stores import module_db  # noqa: F401 (pytest fixtures)

BODY_TIMEOUT_S = HEADER_TIMEOUT_S = 1.0


@pytest.fixture(scope="module")
def srv(module_db):
    db = module_db
    store = open_store(db)
    issued = {name: tokens.issue(store, "device", name) for name in ("dev-a", "dev-b")}
    issued["reader"] = tokens.issue(store, "read")
    issued["revoked"] = tokens.issue(store, "device", "dev-a")
    tokens.revoke(store, issued["revoked"][0])
    store.close()
    with LiveServer(db, access=Access(body_timeout_s=BODY_TIMEOUT_S), header_timeout_s=HEADER_TIMEOUT_S) as server:
        server.tokens = {name: token for name, (_, token) in issued.items()}
        yield server
    # whatever was thrown at it: only the legitimate batches are stored
    stored = set(stored_rows(db, "SELECT device, batch_id FROM batches"))
    assert stored <= {("dev-a", "dev-a:000000"), ("dev-a", "dev-a:000001"), ("dev-b", "dev-a:000000")}
    assert (stored_rows(db, "SELECT MAX(time) FROM objects")[0][0] or 0) < time.time() + 60


def assert_responsive(srv, within_s: float = 1.0) -> None:
    start = time.monotonic()
    status, health = get(srv.url, "/health", timeout=within_s)
    assert status == 200 and time.monotonic() - start < within_s, health


def raw(srv, data: bytes, read_timeout: float = 5.0) -> tuple[bytes, bool]:
    """Send `data` on a fresh connection; (everything the server answered, whether it closed)."""
    with socket.create_connection(("127.0.0.1", srv.port), timeout=read_timeout) as s:
        s.sendall(data)
        return _read_until_closed(s, read_timeout)


def _read_until_closed(s: socket.socket, timeout: float) -> tuple[bytes, bool]:
    s.settimeout(timeout)
    reply = b""
    try:
        while chunk := s.recv(65536):
            reply += chunk
    except TimeoutError:
        return reply, False
    except ConnectionResetError:
        pass
    return reply, True


def status_of(reply: bytes) -> int:
    return int(reply.split(b" ", 2)[1]) if reply.startswith(b"HTTP/1.1 ") else 0


def request_head(srv, length: int | None = None, extra: str = "", token: str | None = None) -> bytes:
    lines = ["POST /detections HTTP/1.1", f"Host: 127.0.0.1:{srv.port}", "Content-Type: application/json"]
    if length is not None:
        lines.append(f"Content-Length: {length}")
    if token:
        lines.append(f"Authorization: Bearer {token}")
    return ("\r\n".join(lines) + "\r\n" + extra + "\r\n").encode()


def batch_a(i: int = 0, **kw) -> dict:
    return make_batch(i, "dev-a", t=time.time() - 60 + i, **kw)


# -- authentication and squatting -----------------------------------------------------------------
def test_posts_without_a_valid_token_are_401_and_another_devices_token_is_403(srv):
    for token in (None, "", "dsfec_nothere_x", srv.tokens["dev-a"][:-2] + "xx", srv.tokens["revoked"]):
        status, body = post(srv.url, batch_a(), token=token)
        assert status == 401 and "token" in body["detail"], (token, body)
    status, body = post(srv.url, batch_a(), token=srv.tokens["dev-b"])  # dev-b squatting dev-a's ids
    assert status == 403 and "dev-b" in body["detail"]
    status, body = post(srv.url, batch_a(), token=srv.tokens["reader"])
    assert status == 403 and "read token" in body["detail"]
    status, body = post(srv.url, b"not json at all", token=None)  # nothing about the body before the token
    assert status == 401
    assert_responsive(srv)


def test_the_401_carries_a_bearer_challenge(srv):
    reply, _ = raw(srv, request_head(srv, 2, "Connection: close\r\n") + b"{}")
    assert status_of(reply) == 401 and b"www-authenticate: Bearer" in reply.lower().replace(b"bearer", b"Bearer")


def test_a_batch_id_lives_in_its_devices_namespace(srv):
    """dev-b posting dev-a's next batch id under its own name neither blocks nor conflicts with dev-a."""
    squat = make_batch(0, "dev-b", t=time.time() - 60)
    squat["batch_id"] = "dev-a:000000"
    assert post(srv.url, squat, token=srv.tokens["dev-b"])[0] == 201
    assert post(srv.url, batch_a(0), token=srv.tokens["dev-a"])[0] == 201  # not a 409
    second = batch_a(1)
    assert post(srv.url, second, token=srv.tokens["dev-a"])[0] == 201
    assert post(srv.url, second, token=srv.tokens["dev-a"])[0] == 200  # the device's own retry


# -- malformed and out-of-range batches -----------------------------------------------------------
MALFORMED = [b"", b"{", b"[]", b"null", b'"text"', b"\xff\xfe{}", b"[" * 100_000, b"1" + b"0" * 5000,
             b'{"batch_id": "x", "batch_id": 1}']


@pytest.mark.parametrize("body", MALFORMED, ids=range(len(MALFORMED)))
def test_malformed_bodies_are_422(srv, body):
    status, reply = post(srv.url, body, token=srv.tokens["dev-a"])
    assert status == 422 and reply["errors"] and reply["detail"].startswith(("body", "batch_id", "device")), reply


NOW = time.time()
OUT_OF_RANGE = [  # (path, value, the field the answer names, words it contains)
    ("time", 1e13, "time", "ahead of the server's clock"),
    ("time", NOW * 1000, "time", "milliseconds"),
    ("time", NOW + 3600, "time", "ahead"),
    ("time", 900_000_000.0, "time", "greater than or equal"),
    ("time", 0.0, "time", "greater than or equal"),
    ("ego.alt", 20_000.0, "ego.alt", "less than"),
    ("ego.alt", -1e6, "ego.alt", "greater than"),
    ("ego.heading_deg", 1e9, "ego.heading_deg", "less than"),
    ("ego.lat", 1e308, "ego.lat", "less than"),
    ("objects.0.alt", 1e12, "objects.0.alt", "less than"),
    ("objects.0.depth_m", 1e7, "objects.0.depth_m", "less than"),
    ("objects.0.depth_m", 0.0, "objects.0.depth_m", "greater than"),
    ("objects.1.x_m", -1e9, "objects.1.x_m", "greater than"),
    ("objects.0.box", [0.0, 0.0, 1e12, 10.0], "objects.0.box.2", "less than"),
    ("objects.0.box", [-1e12, 0.0, 1.0, 10.0], "objects.0.box.0", "greater than"),
    ("objects.0.lat", LAT0 + 0.1, "objects", "from its ego position"),   # ~11 km from the ego
    ("objects.0.lon", LAT0, "objects", "from its ego position"),         # lat and lon swapped
]


@pytest.mark.parametrize("path,value,field,words", OUT_OF_RANGE, ids=[f"{p}={v:g}" if isinstance(v, float) else p
                                                                    for p, v, _, _ in OUT_OF_RANGE])
def test_out_of_range_values_are_422_naming_the_field(srv, path, value, field, words):
    status, body = post(srv.url, changed(batch_a(5), path, value), token=srv.tokens["dev-a"])
    assert status == 422, body
    line = next((e for e in body["errors"] if e.startswith(f"{field}:")), None)
    assert line is not None and words in line, body


def test_non_finite_numbers_are_422(srv):
    for literal in (b"NaN", b"Infinity", b"-Infinity"):
        text = json.dumps(batch_a(6)).encode().replace(b'"depth_m": 12.5', b'"depth_m": ' + literal, 1)
        status, body = post(srv.url, text, token=srv.tokens["dev-a"])
        assert status == 422 and body["errors"][0].startswith("objects.0.depth_m:"), body


# -- bodies: oversized, chunked, lying ------------------------------------------------------------
def test_an_oversized_chunked_body_is_cut_off_at_the_limit(srv):
    """Content-Length: 10 and chunked, then 64 MB: refused, and the server stops reading."""
    chunk = b"x" * 65536
    sent = 0
    with socket.create_connection(("127.0.0.1", srv.port), timeout=5) as s:
        s.sendall(request_head(srv, None, "Transfer-Encoding: chunked\r\n", srv.tokens["dev-a"]))
        try:
            for _ in range(1024):
                s.sendall(b"%x\r\n%s\r\n" % (len(chunk), chunk))
                sent += len(chunk)
        except (BrokenPipeError, ConnectionResetError, TimeoutError):
            pass
        reply, closed = _read_until_closed(s, 5)
    assert status_of(reply) == 413 and closed, reply[:300]
    assert sent < 24 * 2**20, sent  # 2 MB read + what the kernel's socket buffers held; not 64 MB
    assert_responsive(srv)


def test_content_length_with_transfer_encoding_is_400(srv):
    body = json.dumps(batch_a(7)).encode()
    chunked = b"%x\r\n%s\r\n0\r\n\r\n" % (len(body), body)
    reply, closed = raw(srv, request_head(srv, 10, "Transfer-Encoding: chunked\r\n", srv.tokens["dev-a"]) + chunked)
    assert status_of(reply) == 400 and closed, reply[:300]


def test_a_content_length_shorter_than_the_body_stores_nothing(srv):
    body = json.dumps(batch_a(8)).encode()
    reply, _ = raw(srv, request_head(srv, 10, "", srv.tokens["dev-a"]) + body)
    assert status_of(reply) == 422  # the first 10 bytes are the body; the rest is no request (400 or closed)
    assert b"HTTP/1.1 201" not in reply


def test_a_declared_oversize_body_is_413_before_it_is_sent(srv):
    reply, closed = raw(srv, request_head(srv, 10**9, "", srv.tokens["dev-a"]))
    assert status_of(reply) == 413 and closed


# -- slow clients ----------------------------------------------------------------------------------
def test_slow_headers_and_slow_bodies_are_cut_off_and_health_still_answers(srv):
    """20 slowloris connections (a header byte every 0.2 s) and 5 that stall mid-body: the server
    closes each after its deadline; /health answers quickly all along."""
    if not isinstance(srv.db_path, Path):
        pytest.skip("connection deadlines are the server's, not the store's: run on SQLite only")
    slow_heads = [socket.create_connection(("127.0.0.1", srv.port), timeout=5) for _ in range(20)]
    stalled = [socket.create_connection(("127.0.0.1", srv.port), timeout=5) for _ in range(5)]
    try:
        for s in stalled:
            s.sendall(request_head(srv, 1000, "", srv.tokens["dev-a"]) + b'{"batch_id": ')
        head = request_head(srv, 2)
        start = time.monotonic()
        for k in range(int(3 * HEADER_TIMEOUT_S / 0.2)):
            for s in slow_heads:
                try:
                    s.sendall(head[k:k + 1])
                except OSError:
                    pass
            assert_responsive(srv, 0.5)
            time.sleep(0.2)
        assert time.monotonic() - start < 10 * HEADER_TIMEOUT_S
        for s in slow_heads:
            assert _read_until_closed(s, 2)[1]  # closed by the server without a request
        for s in stalled:
            reply, closed = _read_until_closed(s, 2)
            assert status_of(reply) == 408 and closed, reply
    finally:
        for s in slow_heads + stalled:
            s.close()


def test_a_trickled_oversized_header_is_refused(srv):
    """h11 holds at most 16 KB of an incomplete request head (server.MAX_HEADER_BYTES)."""
    head = request_head(srv, 2, "X-Junk: " + "a" * 70_000 + "\r\n") + b"{}"
    with socket.create_connection(("127.0.0.1", srv.port), timeout=5) as s:
        try:
            for k in range(0, len(head), 4096):
                s.sendall(head[k:k + 4096])
                time.sleep(0.005)
        except (BrokenPipeError, ConnectionResetError):
            pass
        reply, closed = _read_until_closed(s, 5)
    assert status_of(reply) == 400 and closed, reply[:200]


# -- hosts and docs --------------------------------------------------------------------------------
@pytest.mark.parametrize("host", ["evil.example", "evil.example:80", "127.0.0.1.evil.example", ""])
def test_a_foreign_host_header_is_400(srv, host):
    body = json.dumps(batch_a(9)).encode()
    head = request_head(srv, len(body), "", srv.tokens["dev-a"]).replace(f"Host: 127.0.0.1:{srv.port}".encode(),
                                                                         f"Host: {host}".encode())
    reply, _ = raw(srv, head + body)
    assert status_of(reply) == 400 and b"not served here" in reply, reply[:300]
    reply, _ = raw(srv, f"GET /objects HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
    assert status_of(reply) == 400


def test_loopback_names_are_served(srv):
    for host in (f"localhost:{srv.port}", "[::1]:8000", "127.0.0.1"):
        reply, _ = raw(srv, f"GET /health HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        assert status_of(reply) == 200, (host, reply[:200])


def test_docs_are_off(srv):
    for path in ("/docs", "/redoc", "/openapi.json"):
        assert get(srv.url, path)[0] == 404

"""The edge uplink against a real map service (uvicorn on a free localhost port): batches queue on
disk while the server is down and arrive exactly once when it is up; a leftover queue is resumed
in order; bad batches and conflicts are set aside with the server's reason; 5xx answers back off."""

from __future__ import annotations

import copy
import http.server
import json
import socket
import sqlite3
import threading
import time

import pytest
import uvicorn

from dsfec_jax.edge.uplink import Uplink
from dsfec_jax.service.app import Access, create_app


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Service:
    """The map service in a daemon thread; start() / stop() may repeat on the same port."""

    def __init__(self, db, port):
        self.db, self.port, self.url = db, port, f"http://127.0.0.1:{port}"

    def start(self):
        self.server = uvicorn.Server(uvicorn.Config(create_app(self.db, access=Access(write_auth=False)), host="127.0.0.1", port=self.port, log_level="warning"))
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started:
            assert time.monotonic() < deadline and self.thread.is_alive(), "uvicorn did not start"
            time.sleep(0.01)
        return self

    def stop(self):
        self.server.should_exit = True
        self.thread.join(10)

    def rows(self, sql):
        with sqlite3.connect(self.db) as conn:
            return conn.execute(sql).fetchall()


@pytest.fixture
def service(tmp_path):
    svc = Service(tmp_path / "map.sqlite", free_port())
    yield svc
    if getattr(svc, "server", None) is not None and svc.thread.is_alive():
        svc.stop()


def batch(i: int, device: str = "dev-01", n: int = 2, lat: float = 49.0069) -> dict:
    return {"batch_id": f"{device}:{i:06d}", "device": device, "frame": f"{i:06d}", "time": 1_790_000_000.0 + 0.1 * i,
            "ego": {"lat": lat, "lon": 8.4037, "alt": 116.4, "heading_deg": 90.0},
            "objects": [{"class": "car", "score": 0.9, "box": [1.0, 2.0, 30.0, 40.0], "depth_m": 10.0 + k, "x_m": 0.5,
                         "lat": 49.0070, "lon": 8.4038 + 1e-5 * k, "alt": 115.0} for k in range(n)]}


def test_a_down_server_queues_to_disk_and_everything_arrives_exactly_once(service, tmp_path):
    link = Uplink(service.url, tmp_path / "queue", timeout_s=2.0, backoff_s=0.05, max_backoff_s=0.2)
    for i in range(5):
        link.send(batch(i, n=i))
    assert len(link.pending()) == 5 and link.counts["sent"] == 0 and link.counts["retried"] >= 1
    assert "Connection refused" in link.last_error or "URLError" in link.last_error
    service.start()
    assert link.flush(10.0)
    assert link.pending() == [] and link.counts["sent"] == 5
    assert service.rows("SELECT COUNT(*), COUNT(DISTINCT batch_id) FROM batches") == [(5, 5)]
    assert service.rows("SELECT COUNT(*) FROM objects") == [(0 + 1 + 2 + 3 + 4,)]
    # delivered oldest first: the server received them in the order they were generated
    assert [r[0] for r in service.rows("SELECT batch_id FROM batches ORDER BY received")] == [f"dev-01:{i:06d}" for i in range(5)]


def test_an_outage_mid_stream_loses_nothing(service, tmp_path):
    """Up, down (the server stops), up again on the same port: every batch once, in order."""
    link = Uplink(service.url, tmp_path / "queue", timeout_s=2.0, backoff_s=0.02, max_backoff_s=0.1)
    service.start()
    for i in range(3):
        assert link.send(batch(i)) == 0
    service.stop()
    for i in range(3, 6):
        link.send(batch(i))
    assert len(link.pending()) == 3
    service.start()
    assert link.send(batch(6)) == 0 or link.flush(10.0)
    assert link.flush(10.0)
    assert [r[0] for r in service.rows("SELECT batch_id FROM batches ORDER BY received")] == [f"dev-01:{i:06d}" for i in range(7)]
    assert link.counts["sent"] == 7 and link.counts["duplicate"] == 0


def test_a_kept_alive_connection_the_server_closed_is_reopened_at_once(service, tmp_path):
    """A server restart between two frames closes the device's kept-alive socket: the next POST
    goes out again on a new connection at once (no backoff, no retry counted)."""
    link = Uplink(service.url, tmp_path / "queue", timeout_s=2.0)
    service.start()
    assert link.send(batch(0)) == 0 and link._http.conn is not None
    service.stop()
    service.start()
    assert link.send(batch(1)) == 0
    assert link.counts == {"sent": 2, "duplicate": 0, "retried": 0, "rejected": 0, "conflicts": 0}


def test_a_leftover_queue_is_resumed_by_a_new_uplink(service, tmp_path):
    first = Uplink(service.url, tmp_path / "queue", timeout_s=2.0)
    for i in range(3):
        first.send(batch(i))
    left = [p.name for p in first.pending()]
    assert left == [f"{i:012d}_dev-01%3A{i:06d}.json" for i in range(3)]
    del first  # the device crashed; its files stay
    service.start()
    second = Uplink(service.url, tmp_path / "queue", timeout_s=2.0)
    assert [p.name for p in second.pending()] == left
    assert second.send(batch(3)) == 0
    assert [r[0] for r in service.rows("SELECT batch_id FROM batches ORDER BY received")] == [f"dev-01:{i:06d}" for i in range(4)]
    assert second.counts["sent"] == 4


def test_a_lost_answer_makes_a_duplicate_not_a_second_copy(service, tmp_path):
    service.start()
    link = Uplink(service.url, tmp_path / "queue")
    link.send(batch(0))
    # the server stored it but the device never saw the 201 (e.g. killed): its file is still queued
    (tmp_path / "queue" / f"{5:012d}_dev-01%3A000000.json").write_text(json.dumps(batch(0)))
    again = Uplink(service.url, tmp_path / "queue")
    assert again.deliver() == 0 and again.counts["duplicate"] == 1 and again.counts["sent"] == 0
    assert service.rows("SELECT COUNT(*) FROM batches") == [(1,)]


def test_a_bad_batch_and_a_conflict_are_set_aside_with_the_reason(service, tmp_path):
    service.start()
    link = Uplink(service.url, tmp_path / "queue")
    bad = batch(1)
    bad["ego"]["lat"] = 95.0
    conflicting = copy.deepcopy(batch(0))
    conflicting["objects"][0]["score"] = 0.1
    for b in (batch(0), bad, conflicting, batch(2)):
        link.send(b)
    assert link.pending() == []
    assert link.counts == {"sent": 2, "duplicate": 0, "retried": 0, "rejected": 1, "conflicts": 1}
    reason = json.loads((tmp_path / "queue" / "rejected" / f"{1:012d}_dev-01%3A000001.reason.json").read_text())
    assert reason["status"] == 422 and any(line.startswith("ego.lat:") for line in reason["reason"]["errors"])
    assert json.loads((tmp_path / "queue" / "rejected" / f"{1:012d}_dev-01%3A000001.json").read_text()) == bad
    conflict = json.loads((tmp_path / "queue" / "conflicts" / f"{2:012d}_dev-01%3A000000.reason.json").read_text())
    assert conflict["status"] == 409 and "different content" in conflict["reason"]["detail"]
    assert service.rows("SELECT batch_id FROM batches ORDER BY batch_id") == [("dev-01:000000",), ("dev-01:000002",)]
    # a restarted device numbers on after the set-aside files: a new rejection cannot overwrite an old one
    again = Uplink(service.url, tmp_path / "queue")
    again.send(batch(5))
    again.send(bad)  # the same bad batch again: were numbering to restart at 0, its name would be taken
    assert len(list((tmp_path / "queue" / "rejected").glob("*.reason.json"))) == 2


class _Unavailable(http.server.BaseHTTPRequestHandler):
    hits = 0

    def do_POST(self):
        type(self).hits += 1
        self.rfile.read(int(self.headers["Content-Length"]))
        self.send_response(503)
        self.send_header("Content-Length", "2")
        self.end_headers()
        self.wfile.write(b"{}")

    def log_message(self, *args):
        pass


def test_a_5xx_keeps_the_batch_and_backs_off(tmp_path):
    stub = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Unavailable)
    threading.Thread(target=stub.serve_forever, daemon=True).start()
    now = [100.0]
    link = Uplink(f"http://127.0.0.1:{stub.server_address[1]}", tmp_path / "queue", backoff_s=1.0, max_backoff_s=4.0,
                  clock=lambda: now[0], sleep=lambda s: now.__setitem__(0, now[0] + s))
    try:
        assert link.send(batch(0)) == 1 and _Unavailable.hits == 1
        assert link.send(batch(1)) == 2 and _Unavailable.hits == 1      # backing off: queued, no attempt
        now[0] += 1.0
        assert link.deliver() == 2 and _Unavailable.hits == 2           # stops at the first failure: keeps order
        assert not link.flush(20.0)                                     # the deadline passes, nothing lost
        assert 4 < _Unavailable.hits < 16                               # waits of 1-2, 2-4, 2-4 ... s, not a busy loop
        assert len(link.pending()) == 2 and link.counts["retried"] == _Unavailable.hits
        assert link.last_error.startswith("HTTP 503")
    finally:
        stub.shutdown()
        stub.server_close()


def test_send_refuses_what_is_not_a_batch_and_ignores_temporaries(tmp_path):
    link = Uplink("http://127.0.0.1:9", tmp_path / "queue")
    with pytest.raises(ValueError, match="batch_id"):
        link.send({"device": "x"})
    nan = batch(0)
    nan["time"] = float("nan")
    with pytest.raises(ValueError, match="JSON"):
        link.send(nan)
    (tmp_path / "queue" / ".000000000000_x.json.abc.tmp").write_text("{")  # an interrupted atomic write
    assert link.pending() == []

"""The edge uplink against a real map service (uvicorn on a free localhost port): batches queue on
disk while the server is down and arrive exactly once when it is up; a leftover queue is resumed
in order; bad batches and conflicts are set aside with the server's reason; 5xx answers back off."""

from __future__ import annotations

import copy
import json
import logging
import os
import pathlib
import socket
import sqlite3
import threading
import time

import pytest
import uvicorn

from edge_fakes import FakeMap

from dsfec_jax.edge.uplink import SpoolFull, Uplink
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
    assert not link.flush(0.2)
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
        link.send(batch(i))
    assert link.flush(10.0)
    service.stop()
    for i in range(3, 6):
        link.send(batch(i))
    assert not link.flush(0.2) and len(link.pending()) == 3
    service.start()
    link.send(batch(6))
    assert link.flush(10.0)
    assert [r[0] for r in service.rows("SELECT batch_id FROM batches ORDER BY received")] == [f"dev-01:{i:06d}" for i in range(7)]
    assert link.counts["sent"] == 7 and link.counts["duplicate"] == 0


def test_a_kept_alive_connection_the_server_closed_is_reopened_at_once(service, tmp_path):
    """A server restart between two frames closes the device's kept-alive socket: the next POST
    goes out again on a new connection at once (no backoff, no retry counted)."""
    link = Uplink(service.url, tmp_path / "queue", timeout_s=2.0)
    service.start()
    link.send(batch(0))
    assert link.flush(10.0) and link._http.conn is not None
    service.stop()
    service.start()
    link.send(batch(1))
    assert link.flush(10.0)
    assert link.counts == {"sent": 2, "duplicate": 0, "retried": 0, "rejected": 0, "conflicts": 0}


def test_a_leftover_queue_is_resumed_by_a_new_uplink(service, tmp_path):
    first = Uplink(service.url, tmp_path / "queue", timeout_s=2.0)
    for i in range(3):
        first.send(batch(i))
    left = [p.name for p in first.pending()]
    assert left == [f"{i:012d}_dev-01%3A{i:06d}.json" for i in range(3)]
    first.close()  # the device crashed; its files stay
    service.start()
    second = Uplink(service.url, tmp_path / "queue", timeout_s=2.0)
    assert [p.name for p in second.pending()] == left
    second.send(batch(3))
    assert second.flush(10.0)
    assert [r[0] for r in service.rows("SELECT batch_id FROM batches ORDER BY received")] == [f"dev-01:{i:06d}" for i in range(4)]
    assert second.counts["sent"] == 4


def test_a_lost_answer_makes_a_duplicate_not_a_second_copy(service, tmp_path):
    service.start()
    link = Uplink(service.url, tmp_path / "queue")
    link.send(batch(0))
    assert link.flush(10.0)
    # the server stored it but the device never saw the 201 (e.g. killed): its file is still queued
    (tmp_path / "queue" / f"{5:012d}_dev-01%3A000000.json").write_text(json.dumps(batch(0)))
    again = Uplink(service.url, tmp_path / "queue")
    assert again.flush(10.0) and again.counts["duplicate"] == 1 and again.counts["sent"] == 0
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
    assert link.flush(10.0) and link.pending() == []
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
    assert again.flush(10.0) and again.summary()["rejected_total"] == 2 and not again.summary()["delivered_all"]
    assert len(list((tmp_path / "queue" / "rejected").glob("*.reason.json"))) == 2


def test_a_5xx_keeps_the_batch_and_backs_off(tmp_path):
    with FakeMap(status=503) as server:
        link = Uplink(server.url, tmp_path / "queue", backoff_s=0.05, max_backoff_s=0.2)
        link.send(batch(0))
        link.send(batch(1))
        start = time.monotonic()
        assert not link.flush(1.0)                                  # the deadline passes, nothing lost
        assert time.monotonic() - start < 1.5 and link.fatal is None
        # waits of 25-50, 50-100, 100-200, 100-200 ... ms, not a busy loop; one attempt per wait, not one per file
        assert 3 <= len(server.answers) <= 16 and set(server.answers) == {503}
        assert len(link.pending()) == 2 and link.counts["retried"] == len(server.answers)
        assert link.last_error.startswith("HTTP 503")
        link.close()


def test_send_refuses_what_is_not_a_batch_and_removes_interrupted_writes(tmp_path):
    link = Uplink("http://127.0.0.1:9", tmp_path / "queue")
    with pytest.raises(ValueError, match="batch_id"):
        link.send({"device": "x"})
    nan = batch(0)
    nan["time"] = float("nan")
    with pytest.raises(ValueError, match="JSON"):
        link.send(nan)
    (tmp_path / "queue" / ".000000000000_x.json.abc.tmp").write_text("{")  # a queue write killed before its rename
    (tmp_path / "queue" / "rejected").mkdir()
    (tmp_path / "queue" / "rejected" / ".000000000001_x.reason.json.abc.tmp").write_text("{")
    again = Uplink("http://127.0.0.1:9", tmp_path / "queue")
    assert again.pending() == [] and sorted(again.spool.removed_temporaries) == [
        ".000000000000_x.json.abc.tmp", "rejected/.000000000001_x.reason.json.abc.tmp"]
    assert sorted(p.name for p in (tmp_path / "queue").rglob("*")) == ["rejected"]


def test_send_never_lists_the_queue_folder_nor_waits_for_the_network(tmp_path, monkeypatch):
    """send() costs its own write whatever the backlog (listing and sorting 50k names cost 2.3 s a
    frame), and the POSTs run in the sender thread (a slow server once stalled the frame loop)."""
    (tmp_path / "queue").mkdir()
    for i in range(200):  # a backlog left by an earlier run
        old = batch(1000 + i, device="old")
        (tmp_path / "queue" / f"{i:012d}_old%3A{1000 + i:06d}.json").write_text(json.dumps(old))
    with FakeMap(delay_s=0.4) as server:
        link = Uplink(server.url, tmp_path / "queue", timeout_s=5.0)
        assert len(link.pending()) == 200

        def no_listing(*args, **kwargs):
            raise AssertionError("send() listed the queue folder")
        for module, name in ((os, "listdir"), (os, "scandir"), (pathlib.Path, "iterdir"), (pathlib.Path, "glob")):
            monkeypatch.setattr(module, name, no_listing)
        start = time.monotonic()
        for i in range(5):
            assert link.send(batch(i)) >= 200
        assert time.monotonic() - start < 1.0          # 5 sends; each POST takes 0.4 s at this server
        monkeypatch.undo()
        link.close()
    assert 1 <= len(server.answers) <= 3 and set(server.answers) == {201} and link.fatal is None
    assert len(link.pending()) == 205 - len(server.answers)


@pytest.mark.parametrize("status", [401, 403, 404, 405, 400, 302])
def test_a_wrong_url_token_or_proxy_stops_the_sender_and_keeps_the_batches(tmp_path, status):
    with FakeMap(status=status) as server:
        link = Uplink(server.url, tmp_path / "queue", backoff_s=0.01)
        for i in range(3):
            link.send(batch(i))
        start = time.monotonic()
        assert not link.flush(5.0) and time.monotonic() - start < 2.0  # fatal: flush does not wait it out
        assert server.answers == [status]                                # one attempt, then it stopped
        assert f"answered HTTP {status}" in link.fatal and server.url in link.fatal
        assert len(link.pending()) == 3 and not (tmp_path / "queue" / "rejected").exists()
        summary = link.summary()
        assert summary["queued"] == 3 and summary["rejected"] == 0 and not summary["delivered_all"]
        link.close()
    hints = {401: "token", 403: "--device", 404: "--server", 405: "--server", 400: "Host", 302: "redirected"}
    assert hints[status] in link.fatal


@pytest.mark.parametrize("body", [b"<html>welcome</html>", b'{"ok": true}'])
def test_a_200_that_is_not_the_map_service_answering_is_fatal(tmp_path, body):
    with FakeMap(body=body) as server:  # e.g. a web server or a mock that takes any POST
        link = Uplink(server.url, tmp_path / "queue")
        link.send(batch(0))
        assert not link.flush(5.0) and "not as the map service answers" in link.fatal
        assert len(link.pending()) == 1 and link.counts["duplicate"] == link.counts["sent"] == 0
        link.close()


def test_the_token_goes_as_a_bearer_header(tmp_path, caplog):
    with FakeMap(token="s3cret-Token_1") as server:
        without = Uplink(server.url, tmp_path / "q1")
        without.send(batch(0))
        assert not without.flush(5.0) and "HTTP 401" in without.fatal and "--token-file" in without.fatal
        with_token = Uplink(server.url, tmp_path / "q2", token="s3cret-Token_1")
        with_token.send(batch(0))
        assert with_token.flush(5.0) and list(server.stored) == ["dev-01:000000"]
        without.close()
        with_token.close()
    assert server.auth == [None, "Bearer s3cret-Token_1"]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="dsfec_jax.edge.uplink"):
        Uplink("http://127.0.0.1:9", tmp_path / "q4", token="t")          # loopback: no warning
        Uplink("https://map.example:8443", tmp_path / "q5", token="t")
        assert caplog.records == []
        Uplink("http://10.1.2.3:8000", tmp_path / "q6", token="t")
    assert "plain http to 10.1.2.3" in caplog.records[0].getMessage()
    for bad in ("two words", "line\nbreak", "", "x" * 5000):
        with pytest.raises(ValueError, match="token") as err:
            Uplink(server.url, tmp_path / "q3", token=bad)
        assert bad not in str(err.value) or not bad


def test_at_its_cap_the_spool_refuses_new_batches_and_keeps_the_old(tmp_path, caplog):
    link = Uplink("http://127.0.0.1:9", tmp_path / "queue", max_queued=5, backoff_s=10.0, room_wait_s=0.1)
    with caplog.at_level(logging.WARNING, logger="dsfec_jax.edge.uplink"):
        for i in range(5):
            link.send(batch(i))
    assert [r.getMessage() for r in caplog.records if "of its cap" in r.getMessage()][0].startswith(
        f"{tmp_path / 'queue'} holds 4 batches")                       # warned once, at 80 %
    with pytest.raises(SpoolFull, match="at its cap .5 batches of 5"):
        link.send(batch(5))
    assert [p.name for p in link.pending()] == [f"{i:012d}_dev-01%3A{i:06d}.json" for i in range(5)]
    assert len(list((tmp_path / "queue").iterdir())) == 5             # nothing written for the refused batch
    link.close()
    with pytest.raises(SpoolFull, match="MB of 0.0 MB"):
        Uplink("http://127.0.0.1:9", tmp_path / "q2", max_queued_bytes=10, room_wait_s=0.0).send(batch(0))


def test_a_queued_file_removed_by_hand_stops_the_sender_loudly(tmp_path):
    link = Uplink("http://127.0.0.1:9", tmp_path / "queue")
    link.spool.write("dev-01:000000", b"{}")                            # on disk, not yet handed over
    path, = link.spool.folder.glob("*.json")
    link.spool.append(path, 2)
    path.unlink()
    assert not link.flush(5.0) and "FileNotFoundError" in link.fatal and str(path) in link.fatal
    link.close()

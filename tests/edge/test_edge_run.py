"""edge.run's loop with the real Uplink and a fake map service (edge_fakes): per-run batch ids, a
killed run's queued-but-unlogged frame, a fatal answer, a full queue; and the command's report."""

from __future__ import annotations

import json
import os
import types

import pytest
from edge_fakes import CheapPipeline, FakeMap, cheap_frames, frame_ids

from dsfec_jax.cli_edge import TOKEN_ENV, read_token, uplink_report
from dsfec_jax.edge.run import BATCHES, done_batches, run_edge
from dsfec_jax.edge.uplink import Uplink


class Counting(CheapPipeline):
    """Counts its calls and puts the call number into the batch: a recomputed frame differs."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.calls: list[str] = []

    def __call__(self, frame, run_id=None):
        result = super().__call__(frame, run_id)
        self.calls.append(frame.frame_id)
        result.batch["objects"][0]["score"] = round(0.01 * len(self.calls), 2)
        return result


DOWN = "http://127.0.0.1:9"  # nothing listens: connection refused


def run(out, url, n, pipeline=None, **uplink_options):
    uplink = Uplink(url, out / "queue", backoff_s=0.01, max_backoff_s=0.05, room_wait_s=0.2, **uplink_options)
    return run_edge(cheap_frames(n), pipeline or CheapPipeline(), out, uplink, flush_s=5.0 if url != DOWN else 0.1)


def test_a_second_drive_is_not_taken_for_the_first(tmp_path):
    """Frame ids restart with each recording: the run id in the batch id keeps drives apart."""
    with FakeMap() as server:
        first = run(tmp_path / "drive0", server.url, 4)
        second = run(tmp_path / "drive1", server.url, 4, CheapPipeline(work_s=0.001))
        again = run(tmp_path / "drive1", server.url, 6)  # a resumed run keeps its id
    assert first["uplink"]["delivered_all"] and second["uplink"]["delivered_all"] and again["uplink"]["delivered_all"]
    assert 409 not in server.answers and len(server.stored) == 10
    assert first["run_id"] != second["run_id"] == again["run_id"]
    assert [b["batch_id"] for b in done_batches(tmp_path / "drive1")] == [
        f"dev-01:{second['run_id']}:{f}" for f in frame_ids(6)]


def test_a_frame_queued_but_not_logged_is_taken_from_the_queue_not_recomputed(tmp_path):
    """A kill between the queue write and the log line: the queued batch is logged on resume; a
    recomputed one could differ (here it does) and meet a 409 at the server."""
    out = tmp_path / "edge"
    with FakeMap() as server:
        first = Counting()
        run(out, DOWN, 3, first)                                         # server down: all three stay queued
        lines = (out / BATCHES).read_bytes().splitlines(keepends=True)
        (out / BATCHES).write_bytes(b"".join(lines[:2]) + lines[2][:25])  # frame 2's line torn by the kill
        second = Counting()
        summary = run(out, server.url, 4, second)
    assert first.calls == frame_ids(3) and second.calls == ["000003"]
    assert summary["frames_resumed"] == 3 and summary["uplink"]["delivered_all"]
    assert [b["frame"] for b in done_batches(out)] == frame_ids(4) and 409 not in server.answers
    assert json.loads(server.stored[done_batches(out)[2]["batch_id"]])["objects"][0]["score"] == 0.03


def test_a_wrong_token_stops_the_run_and_the_next_run_delivers_everything(tmp_path):
    out = tmp_path / "edge"
    with FakeMap(token="right") as server:
        summary = run(out, server.url, 20, CheapPipeline(work_s=0.02), token="wrong")
        assert "HTTP 401" in summary["stopped"] and summary["frames_placed"] < 20
        assert summary["uplink"]["queued"] == summary["frames_placed"] and not summary["uplink"]["delivered_all"]
        assert not (out / "queue" / "rejected").exists() and server.stored == {}
        with pytest.raises(SystemExit, match="not everything was delivered:\n  the server at .* answered HTTP 401"):
            uplink_report(summary, out / "queue")
        fixed = run(out, server.url, 20, token="right")
    assert fixed["stopped"] is None and fixed["uplink"]["delivered_all"] and len(server.stored) == 20
    assert uplink_report(fixed, out / "queue") == 0


def test_a_full_queue_stops_the_run_before_the_frame_and_loses_nothing(tmp_path):
    out = tmp_path / "edge"
    summary = run(out, DOWN, 10, max_queued=4)
    assert "at its cap" in summary["stopped"] and "stopped before frame 000004" in summary["stopped"]
    assert [b["frame"] for b in done_batches(out)] == frame_ids(4) and summary["uplink"]["queued"] == 4
    with FakeMap() as server:
        summary = run(out, server.url, 10, max_queued=4)
    assert summary["stopped"] is None and summary["uplink"]["delivered_all"] and sorted(server.stored) == sorted(
        b["batch_id"] for b in done_batches(out)) and len(server.stored) == 10


def test_the_report_names_what_was_not_delivered(tmp_path, capsys):
    base = {"sent": 3, "duplicate": 0, "retried": 2, "rejected": 1, "conflicts": 1, "queued": 2,
            "rejected_total": 1, "conflicts_total": 1, "fatal": None, "delivered_all": False}
    with pytest.raises(SystemExit) as exit_:
        uplink_report({"stopped": None, "uplink": base}, tmp_path / "queue")
    message = str(exit_.value.code)
    assert "2 batches still queued" in message and "1 batches in" in message and "conflicts" in message
    assert "3 stored, 0 duplicates, 1 rejected, 1 conflicts" in capsys.readouterr().out
    ok = {**base, "rejected": 0, "conflicts": 0, "queued": 0, "rejected_total": 0, "conflicts_total": 0,
          "delivered_all": True}
    assert uplink_report({"stopped": None, "uplink": ok}, tmp_path) == 0
    assert uplink_report({"stopped": None, "uplink": None}, tmp_path) == 0


def test_the_token_comes_from_a_file_or_the_environment(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(TOKEN_ENV, " from-env \n")
    assert read_token(types.SimpleNamespace(token_file=None)) == "from-env"
    path = tmp_path / "token"
    path.write_text("from-file\nsecond line\n")
    os.chmod(path, 0o600)
    assert read_token(types.SimpleNamespace(token_file=str(path))) == "from-file" and capsys.readouterr().err == ""
    os.chmod(path, 0o644)
    assert read_token(types.SimpleNamespace(token_file=str(path))) == "from-file"
    assert "readable by others" in capsys.readouterr().err
    path.write_text("\n")
    with pytest.raises(ValueError, match="first line is empty"):
        read_token(types.SimpleNamespace(token_file=str(path)))
    monkeypatch.delenv(TOKEN_ENV)
    assert read_token(types.SimpleNamespace(token_file=None)) is None


def test_a_log_line_or_queued_file_changed_by_hand_is_named(tmp_path):
    out = tmp_path / "edge"
    run(out, DOWN, 2)
    queued = sorted((out / "queue").glob("*.json"))
    (out / BATCHES).write_text("")                                       # both frames now need recovering
    queued[1].write_text(json.dumps({"batch_id": "someone-else:1", "frame": "000001"}))
    with pytest.raises(ValueError, match=f"{queued[1].name}: expected the frame batch 'dev-01:.*:000001'"):
        run(out, DOWN, 2)
    (out / BATCHES).write_text('{"batch_id": "a", "frame": "0"}\n{"batch_id": \n{"batch_id": "b", "frame": "1"}\n')
    with pytest.raises(ValueError, match=f"{BATCHES} line 2: not a frame batch"):
        run(out, DOWN, 2)


def test_resuming_an_out_dir_for_another_recording_is_refused_naming_the_field(tmp_path):
    """Frame ids restart with each recording: resuming drive 0's folder for drive 1 (or as another
    device) would skip frames never computed, so run.json's recording must match."""
    out = tmp_path / "edge"
    drive0 = {"device": "dev-01", "source": {"index": 0}}
    run_edge(cheap_frames(2), CheapPipeline(), out, recording=drive0)
    summary = run_edge(cheap_frames(3), CheapPipeline(), out, recording=drive0)  # the same recording resumes
    assert summary["frames_resumed"] == 2 and summary["frames_placed"] == 3
    for changed in ({**drive0, "source": {"index": 1}}, {**drive0, "device": "dev-02"}):
        field = next(k for k in changed if changed[k] != drive0[k])
        with pytest.raises(ValueError, match=f"recording.{field} is"):
            run_edge(cheap_frames(3), CheapPipeline(), out, recording=changed)
    assert [b["frame"] for b in done_batches(out)] == frame_ids(3)

"""kill -9 of the edge loop at any instant loses no frame and posts none twice: edge.run's real loop
and the real Uplink (edge_kill_child.py) against a fake map service that keeps batches as the real
one does. 12 runs die just before one of their fsync / rename / unlink calls, 2 more are killed
from outside mid-loop, and a last run finishes; every batch then sits at the server exactly once."""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
from pathlib import Path

from edge_fakes import FakeMap, frame_ids

from dsfec_jax.edge.run import BATCHES, done_batches
from dsfec_jax.core.atomic import is_temporary
from dsfec_jax.edge.spool import batch_id_of

CHILD = Path(__file__).resolve().parent / "edge_kill_child.py"
FRAMES = 30


def child(out: Path, url: str, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(CHILD), str(out), url, str(FRAMES), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def check_logged_frames_are_kept(out: Path, server: FakeMap) -> None:
    """After a kill: every frame in the log is queued or at the server (else a resume skips it and
    nobody ever sends it), and no frame is logged twice."""
    logged = [b["batch_id"] for b in done_batches(out)]
    queued = {batch_id_of(p) for p in (out / "queue").glob("*.json")}
    assert len(logged) == len(set(logged))
    lost = set(logged) - queued - set(server.stored)
    assert not lost, f"logged but neither queued nor delivered: {sorted(lost)}"


def test_kill_9_at_any_instant_loses_no_frame(tmp_path):
    out, rng, kills = tmp_path / "edge", random.Random(0), 0
    with FakeMap() as server:
        for k in range(1, 13):  # the k-th fsync/rename/unlink: each edge between a frame's writes
            proc = child(out, server.url, "--die-at", str(k))
            proc.communicate(timeout=60)
            kills += proc.returncode == -signal.SIGKILL
            check_logged_frames_are_kept(out, server)
        for _ in range(2):  # from outside, a few frames into the loop
            proc = child(out, server.url, "--work-s", "0.002")
            for _ in range(rng.randint(1, 4)):
                proc.stdout.readline()
            proc.send_signal(signal.SIGKILL)
            proc.communicate(timeout=60)
            kills += proc.returncode == -signal.SIGKILL
            check_logged_frames_are_kept(out, server)
        last = child(out, server.url)
        stdout, stderr = last.communicate(timeout=60)
        assert last.returncode == 0, stderr
    assert kills >= 10
    run_id = json.loads((out / "run.json").read_text())["run_id"]
    expected = [f"dev-01:{run_id}:{f}" for f in frame_ids(FRAMES)]
    log = done_batches(out)
    assert [b["batch_id"] for b in log] == expected                      # each frame logged once, in order
    assert sorted(server.stored) == expected and 409 not in server.answers  # each at the server once
    assert all(json.loads(server.stored[b["batch_id"]]) == b for b in log)
    assert json.loads(stdout.splitlines()[-1])["delivered_all"]
    left = [p.name for p in (out / "queue").rglob("*")]
    assert left == [], left                                               # nothing queued, set aside or temporary
    assert not any(is_temporary(p.name) for p in out.iterdir() if p.name != BATCHES)

"""A fleet of simulated edge devices against the map service on localhost: load test and kill test.

    python -m dsfec_jax.edge.loadtest --devices 8 --seconds 20 --out runs/loadtest
    python -m dsfec_jax.edge.loadtest --devices 8 --seconds 20 --kill-at 8 --out runs/loadtest
    python -m dsfec_jax.edge.loadtest --devices 8 --seconds 20 --db postgresql://USER@HOST/DB --workers 2 --out runs/loadtest

It lives on the devices' side of the wire: it starts the server as a separate process
(`python -m dsfec_jax.service`, uvicorn, a fresh database on a free localhost port, write tokens
on: one device token per simulated device, issued with `python -m dsfec_jax.service token add`), talks to it
only over HTTP through edge.uplink.Uplink, and reads its database file with sqlite3 afterwards; it
imports nothing of service/ (tests/test_architecture.py: edge and service meet only over HTTP).
With --db postgresql://... the service stores into a fresh schema of that database (created for
the run, read back with psycopg, dropped at the end) and may run --workers processes.

N simulated devices (threads) each drive their own track and post one frame batch per frame (0-2K
objects placed ahead of the ego with the issue's placement formula and pymap3d), each through its
own Uplink and disk queue, for T seconds; then every device flushes its queue. `--rate 0` (the
default) is a closed loop: a device makes its next frame as soon as the previous one was delivered
(send() only queues it: the uplink's sender thread posts, so the loop waits on flush()), which
measures capacity; `--rate 10` is a 10 fps camera. With --kill-at S the server (its supervisor and every worker: the
process group) is SIGKILLed S seconds in and restarted on the same port and database --pause seconds later, while the devices
keep generating (their uplinks queue and retry).

Checked afterwards in the database file: the stored batch ids are exactly the generated ones (none
missing, none extra, none twice), every stored batch and object holds exactly the values its device
generated, no object is orphaned, the totals agree, the per-device counters agree with the rows, PRAGMA integrity_check is ok (SQLite), and every
device's queue is empty with nothing rejected.

Figures: requests/s (delivered POSTs over the whole run, final flush included), p50 / p99 / max
latency of the delivered POSTs (client side, http.client on each device's kept-alive connection),
failed attempts (retried), duplicates (a retry of a batch whose first attempt was stored but
unanswered), the outage, the server's CPU per POST, and each device's cost of queueing a frame
durably (two fsyncs: core/atomic.py). The devices run in this process and share the machine's
cores and disk with the server: on a small machine the figures are a floor for the server; the
load average at the end is in the record. The record (command, seed, versions, figures, checks)
is written atomically to OUT/loadtest[_kill].json; the exit status is 1 if a check fails.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import random
import re
import signal
import socket
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pymap3d

from ..core.atomic import write_json
from ..core.pg_scratch import scratch_schema
from ..core.provenance import versions
from .uplink import Uplink

ORIGIN = (49.0069, 8.4037, 115.0)  # Karlsruhe (the street benchmark's origin): lat, lon, height
CLASSES = ("car", "truck", "bus", "pedestrian", "cyclist")
IMAGE_W, IMAGE_H, FX = 416, 234, 350.0  # a small dashcam (box geometry only)


# -- the simulated device ------------------------------------------------------------------------
class Device:
    """One edge device: an ego driving a smooth random track from its own start point, placing
    0-2K objects per frame ahead of it. Deterministic from (seed, index)."""

    def __init__(self, index: int, seed: int, objects_per_frame: int):
        self.name = f"dev-{index:02d}"
        self.rng = random.Random(seed * 1000 + index)
        self.k = objects_per_frame
        self.e, self.n = 400.0 * index, 150.0 * (index % 3)  # devices 400 m apart
        self.heading = self.rng.uniform(0, 2 * math.pi)        # compass, clockwise from north
        self.speed = self.rng.uniform(6.0, 14.0)
        self.frame = 0

    def next_batch(self, dt: float) -> dict:
        r = self.rng
        self.heading += r.gauss(0.0, 0.02)
        self.e += self.speed * dt * math.sin(self.heading)
        self.n += self.speed * dt * math.cos(self.heading)
        n_obj = r.randint(0, 2 * self.k)
        depth = np.array([r.uniform(4.0, 60.0) for _ in range(n_obj)])
        x = np.array([r.uniform(-8.0, 8.0) for _ in range(n_obj)])
        s, c = math.sin(self.heading), math.cos(self.heading)
        # the issue's placement: E = E0 + d sin(psi) + x cos(psi), N = N0 + d cos(psi) - x sin(psi)
        east = np.concatenate([[self.e], self.e + depth * s + x * c])
        north = np.concatenate([[self.n], self.n + depth * c - x * s])
        up = np.concatenate([[1.4], np.full(n_obj, 0.8)])
        lat, lon, alt = (np.atleast_1d(v) for v in pymap3d.enu2geodetic(east, north, up, *ORIGIN))
        objects = [self._object(r, float(depth[i]), float(x[i]), float(lat[i + 1]), float(lon[i + 1]), float(alt[i + 1]))
                   for i in range(n_obj)]
        batch = {"batch_id": f"{self.name}:{self.frame:07d}", "device": self.name, "frame": f"{self.frame:07d}",
                 "time": time.time(), "ego": {"lat": float(lat[0]), "lon": float(lon[0]), "alt": float(alt[0]),
                                              "heading_deg": math.degrees(self.heading) % 360.0},
                 "objects": objects}
        self.frame += 1
        return batch

    @staticmethod
    def _object(r: random.Random, depth: float, x: float, lat: float, lon: float, alt: float) -> dict:
        cls = r.choice(CLASSES)
        u = IMAGE_W / 2 + FX * x / depth
        half_w = FX * (1.0 if cls in ("pedestrian", "cyclist") else 2.0) / depth / 2
        height = FX * (1.7 if cls in ("pedestrian", "cyclist", "car") else 3.2) / depth
        v2 = IMAGE_H / 2 + FX * 1.4 / depth
        box = [min(max(u - half_w, 0.0), IMAGE_W), max(v2 - height, 0.0), min(max(u + half_w, 0.0), IMAGE_W), min(v2, IMAGE_H)]
        return {"class": cls, "score": round(r.uniform(0.3, 1.0), 4), "box": [round(b, 1) for b in box],
                "depth_m": round(depth, 3), "x_m": round(x, 3), "lat": lat, "lon": lon, "alt": alt}


class DeviceRun(threading.Thread):
    """Generates and sends frames until `stop_at` (monotonic), then flushes its queue."""

    def __init__(self, device: Device, url: str, queue_dir: Path, rate: float, stop_at: float, flush_s: float,
                 token: str | None = None):
        super().__init__(name=device.name, daemon=True)
        self.device, self.rate, self.stop_at, self.flush_s = device, rate, stop_at, flush_s
        self.latencies: list[float] = []      # seconds of the POSTs that delivered (200/201)
        self.failures = 0                     # POST attempts without a 200/201 answer
        self.post_s = 0.0                     # seconds in POSTs (all attempts)
        self.send_s = 0.0                     # seconds in send(): the durable queue write (a sender thread posts)
        self.max_queued = 0
        self.generated: dict[str, dict] = {}  # batch_id -> batch
        self.flushed = False
        self.uplink = Uplink(url, queue_dir, timeout_s=5.0, backoff_s=0.1, max_backoff_s=1.0, observer=self._observe,
                             token=token)

    def _observe(self, status, seconds):
        self.post_s += seconds
        if status in (200, 201):
            self.latencies.append(seconds)
        else:
            self.failures += 1

    def run(self):
        start, dt = time.monotonic(), 1.0 / self.rate if self.rate > 0 else 0.1
        while time.monotonic() < self.stop_at:
            batch = self.device.next_batch(dt)
            self.generated[batch["batch_id"]] = batch
            t = time.monotonic()
            self.max_queued = max(self.max_queued, self.uplink.send(batch))
            self.send_s += time.monotonic() - t
            if self.rate > 0:  # a camera: the next frame comes at its time, whatever the network did
                time.sleep(max(0.0, start + self.device.frame * dt - time.monotonic()))
            else:  # closed loop: the next frame once this one is delivered (or the run's time is up)
                self.uplink.flush(max(0.0, min(self.flush_s, self.stop_at - time.monotonic())))
        self.flushed = self.uplink.flush(self.flush_s)


# -- the server process --------------------------------------------------------------------------
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def issue_tokens(db: Path | str, names: list[str]) -> dict[str, str]:
    """One device token per simulated device, issued by the service's own admin command (over
    the database file, before the server starts): device name -> token."""
    cmd = [sys.executable, "-m", "dsfec_jax.service", "token", "add", "--db", str(db), "--json",
           *(arg for name in names for arg in ("--device", name))]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    if out.returncode != 0:
        raise RuntimeError(f"issuing device tokens failed: {out.stderr.strip()}")
    return {item["device"]: item["token"] for item in json.loads(out.stdout)}


def start_server(db: Path | str, port: int, log: Path, synchronous: str = "FULL", workers: int = 1) -> subprocess.Popen:
    """The service in a process group of its own (its workers included), so a kill reaches all of it."""
    cmd = [sys.executable, "-m", "dsfec_jax.service", "--db", str(db), "--port", str(port), "--log-level", "warning",
           "--synchronous", synchronous, "--workers", str(workers)]
    with open(log, "ab") as out:
        return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)


def wait_healthy(url: str, proc: subprocess.Popen, timeout_s: float = 30.0) -> float:
    """Seconds until GET /health answers; raises if the process dies or the time runs out."""
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if proc.poll() is not None:
            raise RuntimeError(f"the server exited with status {proc.returncode} before answering /health")
        try:
            with urllib.request.urlopen(url + "/health", timeout=1.0) as reply:
                if reply.status == 200:
                    return time.monotonic() - start
        except OSError:
            time.sleep(0.02)
    raise RuntimeError(f"{url}/health did not answer within {timeout_s} s")


def unauthenticated_post_status(url: str) -> int:
    """The server's answer to a post without a token: 401 when write tokens are on, as they must be."""
    req = urllib.request.Request(url + "/detections", data=b"{}", method="POST", headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=5.0) as reply:
            return reply.status
    except urllib.error.HTTPError as e:
        return e.code


def cpu_seconds(session: int) -> float | None:
    """User + system CPU seconds so far of the processes of a session (the server and its workers;
    Linux /proc; None elsewhere)."""
    total, found = 0, False
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue  # a process that ended meanwhile
        if len(fields) > 12 and fields[3] == str(session):
            total, found = total + int(fields[11]) + int(fields[12]), True
    return total / os.sysconf("SC_CLK_TCK") if found else None


def stop_server(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGINT)  # uvicorn's graceful shutdown (the supervisor stops its workers)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        pass
    kill_group(proc)


def kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL the server's process group (start_server made one) and reap its leader."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


RESTART_TIMEOUT_S = 120.0  # a restarted server's workers start on a machine the devices keep busy


class Killer(threading.Thread):
    """At `at_s` after `t0`: SIGKILL the server, wait `pause_s`, start it again, wait for /health."""

    def __init__(self, server: dict, at_s: float, pause_s: float, t0: float, start):
        super().__init__(daemon=True)
        self.server, self.at_s, self.pause_s, self.t0, self.start_fn = server, at_s, pause_s, t0, start
        self.figures: dict = {}

    def run(self):
        time.sleep(max(0.0, self.t0 + self.at_s - time.monotonic()))
        killed = time.monotonic()
        kill_group(self.server["proc"])
        time.sleep(self.pause_s)
        self.server["proc"] = self.start_fn()
        self.figures = {"killed_at_s": round(killed - self.t0, 3), "pause_s": self.pause_s}
        try:
            startup = wait_healthy(self.server["url"], self.server["proc"], RESTART_TIMEOUT_S)
        except RuntimeError as e:  # said in the record and fails the run, not lost in this thread
            self.figures["restart_error"] = str(e)
            return
        self.figures.update(restart_to_healthy_s=round(startup, 3), outage_s=round(time.monotonic() - killed, 3))


# -- checks and figures --------------------------------------------------------------------------
BATCH_SQL = "SELECT batch_id, device, frame, time, ego_lat, ego_lon, ego_alt, ego_heading_deg, n_objects FROM batches"
OBJECT_SQL = ("SELECT batch_id, class, score, box_x1, box_y1, box_x2, box_y2, depth_m, x_m, lat, lon, alt"
              " FROM objects ORDER BY batch_id, idx")


def batch_row(b: dict) -> tuple:
    e = b["ego"]
    return (b["batch_id"], b["device"], b["frame"], b["time"], e["lat"], e["lon"], e["alt"], e["heading_deg"],
            len(b["objects"]))


def object_rows(b: dict) -> list[tuple]:
    return [(b["batch_id"], o["class"], o["score"], *o["box"], o["depth_m"], o["x_m"], o["lat"], o["lon"], o["alt"])
            for o in b["objects"]]


COUNTER_SQL = ("SELECT COUNT(*) FROM devices d FULL OUTER JOIN (SELECT device, COUNT(*) AS n, SUM(n_objects) AS k"
               " FROM batches GROUP BY device) r ON d.device = r.device"
               " WHERE d.device IS NULL OR r.device IS NULL OR d.batches != r.n OR d.objects != r.k")


def read_database(db: Path | str) -> tuple[list[tuple], list[tuple], int, str | None, str]:
    """(batch rows, object rows, devices whose counters disagree with the rows, SQLite's
    integrity_check or None, journal mode) of the service's database: a SQLite file opened
    read-only, or a PostgreSQL URL read in one read-only transaction."""
    if isinstance(db, str) and db.startswith(("postgresql://", "postgres://")):
        import psycopg  # the `postgres` extra: only for a PostgreSQL run

        with psycopg.connect(db, connect_timeout=10) as conn:
            conn.read_only = True
            return (conn.execute(BATCH_SQL).fetchall(), conn.execute(OBJECT_SQL).fetchall(),
                    conn.execute(COUNTER_SQL).fetchone()[0], None, "postgresql")
    conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True)  # read-only: the check must not change what it checks
    try:
        return (conn.execute(BATCH_SQL).fetchall(), conn.execute(OBJECT_SQL).fetchall(),
                conn.execute(COUNTER_SQL).fetchone()[0],  # FULL OUTER JOIN: SQLite 3.39 or later
                conn.execute("PRAGMA integrity_check").fetchone()[0], conn.execute("PRAGMA journal_mode").fetchone()[0])
    finally:
        conn.close()


def check_database(db: Path | str, generated: dict[str, dict]) -> dict:
    """Every generated batch stored exactly once, with exactly its values and its objects (in the
    service's tables: a float survives JSON and the database's double bit for bit); nothing else
    stored; the per-device counters agree with the rows."""
    rows, object_list, counter_mismatches, integrity, journal = read_database(db)
    objects: dict[str, list[tuple]] = {}
    for row in object_list:
        objects.setdefault(row[0], []).append(row)
    stored = {r[0]: r for r in rows}
    missing = sorted(set(generated) - set(stored))
    extra = sorted(set(stored) - set(generated))
    wrong_batch = [b for b, batch in generated.items() if b in stored and stored[b] != batch_row(batch)]
    wrong_objects = [b for b, batch in generated.items() if b in stored and objects.get(b, []) != object_rows(batch)]
    expected_objects = sum(len(b["objects"]) for b in generated.values())
    stored_objects = sum(map(len, objects.values()))
    checks = {"batches_generated": len(generated), "batches_stored": len(rows),
              "distinct_batch_ids_stored": len(stored), "missing": len(missing), "extra": len(extra),
              "batch_value_mismatches": len(wrong_batch), "object_mismatches": len(wrong_objects),
              "objects_generated": expected_objects, "objects_stored": stored_objects,
              "orphan_objects": len(set(objects) - set(stored)), "device_counter_mismatches": counter_mismatches,
              "integrity_check": integrity, "journal_mode": journal,
              "examples": {"missing": missing[:5], "extra": extra[:5], "batch": wrong_batch[:5], "objects": wrong_objects[:5]}}
    checks["exactly_once"] = (len(rows) == len(stored) == len(generated) and not missing and not extra
                              and not wrong_batch and not wrong_objects and stored_objects == expected_objects
                              and not checks["orphan_objects"] and not counter_mismatches and integrity in ("ok", None))
    return checks


def latency_ms(seconds: list[float]) -> dict:
    if not seconds:
        return {"p50": None, "p99": None, "max": None, "mean": None}
    q = np.percentile(np.asarray(seconds) * 1e3, [50, 99])
    return {"p50": round(float(q[0]), 2), "p99": round(float(q[1]), 2), "max": round(max(seconds) * 1e3, 2),
            "mean": round(statistics.fmean(seconds) * 1e3, 2)}


# -- the run -------------------------------------------------------------------------------------
def run(devices: int, seconds: float, kill_at: float | None, pause_s: float, rate: float, objects: int,
        seed: int, workdir: Path, flush_s: float, synchronous: str = "FULL", db: str | None = None,
        workers: int = 1) -> dict:
    """The load (and kill) test against the service on a SQLite file in `workdir`, or on the
    PostgreSQL database `db` (a URL: the caller gives it an empty schema) with `workers` processes."""
    db, port = db or workdir / "map.sqlite", free_port()
    url = f"http://127.0.0.1:{port}"
    log = workdir / "server.log"
    fleet = [Device(i, seed, objects) for i in range(devices)]
    device_tokens = issue_tokens(db, [d.name for d in fleet])
    server = {"url": url, "proc": start_server(db, port, log, synchronous, workers)}
    try:
        startup = wait_healthy(url, server["proc"])
        no_token_status = unauthenticated_post_status(url)
        t0 = time.monotonic()
        runs = [DeviceRun(d, url, workdir / "queues" / d.name, rate, t0 + seconds, flush_s, device_tokens[d.name])
                for d in fleet]
        killer = Killer(server, kill_at, pause_s, t0, lambda: start_server(db, port, log, synchronous, workers)) \
            if kill_at is not None else None
        for r in runs:
            r.start()
        if killer:
            killer.start()
        for r in runs:
            r.join()
        done = time.monotonic()
        if killer:
            killer.join()
        server_cpu = cpu_seconds(server["proc"].pid)  # the last server's (the restarted one after a kill), workers included
    finally:
        stop_server(server["proc"])  # never leave a server behind, whatever failed

    generated = {k: v for r in runs for k, v in r.generated.items()}
    counts = {k: sum(r.uplink.counts[k] for r in runs) for k in runs[0].uplink.counts}
    latencies = [s for r in runs for s in r.latencies]
    delivered = counts["sent"] + counts["duplicate"]
    checks = check_database(db, generated)
    checks["queues_empty"] = all(r.flushed and not r.uplink.pending() for r in runs)
    checks["rejected_or_conflicts"] = counts["rejected"] + counts["conflicts"]
    checks["post_without_token_status"] = no_token_status
    checks["restarted"] = killer is None or "restart_error" not in killer.figures
    checks["passed"] = (checks["exactly_once"] and checks["queues_empty"] and checks["rejected_or_conflicts"] == 0
                        and no_token_status == 401 and checks["restarted"])
    return {
        "figures": {"devices": devices, "load_seconds": seconds, "rate_per_device_hz": rate or "closed loop",
                    "synchronous": synchronous, "store": "sqlite" if isinstance(db, Path) else "postgresql",
                    "server_workers": workers,
                    "server_startup_s": round(startup, 3), "wall_incl_flush_s": round(done - t0, 3),
                    "posts_delivered": delivered, "requests_per_s": round(delivered / (done - t0), 1),
                    "frames_per_s_generated": round(len(generated) / seconds, 1),
                    "objects_per_s": round(checks["objects_stored"] / (done - t0), 1),
                    "latency_ms": latency_ms(latencies), "failed_attempts": sum(r.failures for r in runs),
                    "server_cpu_ms_per_post": None if server_cpu is None or killer else round(1e3 * server_cpu / max(delivered, 1), 3),
                    "device_queue_write_ms_per_frame": round(1e3 * sum(r.send_s for r in runs) / max(len(generated), 1), 3),
                    "max_queued_per_device": max(r.max_queued for r in runs),
                    "uplink_counts": counts, "kill": killer.figures if killer else None,
                    "db_bytes": db.stat().st_size if isinstance(db, Path) else None},
        "checks": checks,
        "server_log_tail": log.read_text(errors="replace")[-2000:],
    }


def without_password(value):
    """A command-line value with the password of a URL in it (user:PASSWORD@) starred out."""
    return re.sub(r"(://[^:/@]*:)[^@]*@", r"\1***@", value) if isinstance(value, str) else value


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.edge.loadtest", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--devices", type=int, default=8)
    p.add_argument("--seconds", type=float, default=20.0, help="how long the devices generate frames")
    p.add_argument("--kill-at", type=float, default=None, help="SIGKILL the server this many seconds in, then restart it")
    p.add_argument("--pause", type=float, default=1.0, help="seconds the killed server stays down before the restart")
    p.add_argument("--rate", type=float, default=0.0, help="frames/s per device; 0 = closed loop (capacity)")
    p.add_argument("--objects", type=int, default=3, help="mean objects per frame (uniform 0..2K)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--synchronous", default="FULL", choices=["FULL", "NORMAL"],
                   help="the server's SQLite synchronous mode (FULL: fsync before each 201)")
    p.add_argument("--db", default=None, metavar="URL",
                   help="a PostgreSQL database (postgresql://...): the service stores into a fresh schema of it, dropped "
                        "afterwards; default: a SQLite file in the work folder")
    p.add_argument("--workers", type=int, default=1, help="server processes (PostgreSQL only)")
    p.add_argument("--flush", type=float, default=60.0, help="seconds each device may take to empty its queue at the end")
    p.add_argument("--workdir", type=Path, default=None,
                   help="keep the database, queues and server log here (default: a temporary folder, removed)")
    p.add_argument("--out", type=Path, required=True, help="folder for the JSON record")
    a = p.parse_args(argv)
    if a.devices < 1 or a.seconds <= 0 or (a.kill_at is not None and not 0 < a.kill_at < a.seconds):
        p.error("need --devices >= 1, --seconds > 0 and 0 < --kill-at < --seconds")
    if a.db is not None and not a.db.startswith(("postgresql://", "postgres://")):
        p.error(f"--db {a.db!r}: expected a postgresql:// URL (without --db the test uses a SQLite file)")
    if a.workers != 1 and a.db is None:
        p.error("--workers needs --db postgresql://... (the service runs one process on SQLite)")
    with tempfile.TemporaryDirectory(prefix="dsfec-loadtest-") as tmp, \
            (scratch_schema(a.db, "loadtest") if a.db else contextlib.nullcontext()) as schema_url:
        workdir = a.workdir or Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        result = run(a.devices, a.seconds, a.kill_at, a.pause, a.rate, a.objects, a.seed, workdir, a.flush, a.synchronous,
                     schema_url, a.workers)
    argv = [without_password(v) for v in (argv if argv is not None else sys.argv[1:])]
    record = {"command": " ".join(["python -m dsfec_jax.edge.loadtest", *argv]), "seed": a.seed,
              "options": {k: str(v) if isinstance(v, Path) else without_password(v) for k, v in vars(a).items()},
              "versions": versions(("fastapi", "uvicorn", "starlette", "pydantic", "pymap3d", "numpy", "dsfec_jax")),
              "machine": {"cpus": os.cpu_count(), "load_average_1_5_15min_at_end": os.getloadavg(), "sqlite": sqlite3.sqlite_version,
                          "workdir": str(a.workdir) if a.workdir else "(temporary, removed)"}, **result}
    out = a.out / ("loadtest_kill.json" if a.kill_at is not None else "loadtest.json")
    write_json(out, record)
    print(json.dumps({"out": str(out), **record["figures"], "passed": result["checks"]["passed"],
                      "exactly_once": result["checks"]["exactly_once"]}, indent=1))
    return 0 if result["checks"]["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())

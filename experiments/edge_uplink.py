"""The edge uplink's cost on the frame loop (issue 49): send() with a backlog, and the stall after
an outage, against the real map service (`python -m dsfec_jax.service --no-auth`, a fresh database
on a free localhost port).

    python -m experiments.edge_uplink [--queued 0,50000] [--outage-s 120] [--fps 17] [--tag after]
                                      [--out experiments/records/edge]

- send(): a queue pre-filled with N batch files, then --sends sends with the server up and with
  nothing listening (connection refused): median / max ms per send(), and the time to open the
  Uplink on that queue.
- outage: a --fps frames/s loop (sleep to the frame's time, then send()) for 10 s, the server
  SIGKILLed for --outage-s and restarted on the same port and database, 60 s more: the longest time
  one frame spent in send() after the restart, frames over 100 ms, median / p99, how long after the
  restart the queue was empty again, and whether every batch arrived.

Only Uplink's public API (send, flush, pending) is used, so the same script measures an older
tree: `git archive 9bc6325 dsfec_jax | tar -x -C /tmp/old`, then `PYTHONPATH=/tmp/old:. python -m
experiments.edge_uplink --tag before` (that tree's service has no --no-auth: --service-args '').
Writes edge_uplink_<tag>.json (command, versions, the code measured, figures) atomically to --out.
"""

from __future__ import annotations

import argparse
import inspect
import json
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from dsfec_jax.core import atomic
from dsfec_jax.core.provenance import versions
from dsfec_jax.edge.uplink import Uplink


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_service(db: Path, port: int, extra: list[str]) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "dsfec_jax.service", "--db", str(db), "--port", str(port), "--log-level", "warning"]
    proc = subprocess.Popen(cmd + extra, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=1).read()
            return proc
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"the map service did not start ({' '.join(cmd + extra)})")


def batch(i: int, device: str = "bench") -> dict:
    lat = 49.0069 + 1e-5 * (i % 1000)
    return {"batch_id": f"{device}:{i:07d}", "device": device, "frame": f"{i:07d}", "time": time.time(),
            "ego": {"lat": lat, "lon": 8.4037, "alt": 116.4, "heading_deg": 0.0},
            "objects": [{"class": "car", "score": 0.9, "box": [1.0, 2.0, 30.0, 40.0], "depth_m": 10.0 + k, "x_m": 0.5,
                         "lat": lat + 1e-4, "lon": 8.4038 + 1e-5 * k, "alt": 115.0} for k in range(3)]}


def open_uplink(url: str, queue: Path) -> Uplink:
    cap = {"max_queued": 10 ** 6} if "max_queued" in inspect.signature(Uplink).parameters else {}  # no cap before
    return Uplink(url, queue, timeout_s=5.0, **cap)


def close(link: Uplink) -> None:
    if hasattr(link, "close"):  # a sender thread (after the fix) stops before its folder goes
        link.close()


def ms(seconds: float) -> float:
    return round(1e3 * seconds, 2)


def measure_send(queued: int, server_up: bool, sends: int, service_args: list[str], work: Path) -> dict:
    queue = work / "queue"
    queue.mkdir(parents=True)
    for i in range(queued):
        (queue / f"{i:012d}_old%3A{i:07d}.json").write_text(json.dumps(batch(i, "old")))
    port = free_port()
    server = start_service(work / "map.sqlite", port, service_args) if server_up else None
    try:
        start = time.perf_counter()
        link = open_uplink(f"http://127.0.0.1:{port}", queue)
        opened, times = time.perf_counter() - start, []
        for i in range(sends):
            start = time.perf_counter()
            link.send(batch(10 ** 6 + i))
            times.append(time.perf_counter() - start)
        close(link)
    finally:
        if server is not None:
            server.kill()
    return {"queued": queued, "server": "up" if server_up else "down", "sends": sends, "open_ms": ms(opened),
            "median_ms": ms(statistics.median(times)), "max_ms": ms(max(times))}


def measure_outage(outage_s: float, fps: float, service_args: list[str], work: Path) -> dict:
    port, db = free_port(), work / "map.sqlite"
    server = start_service(db, port, service_args)
    link = open_uplink(f"http://127.0.0.1:{port}", work / "queue")
    dt, start, i = 1.0 / fps, time.monotonic(), 0
    kill_at, restart_at, end_at = 10.0, 10.0 + outage_s, 70.0 + outage_s
    after, empty_at, restarted = [], None, None
    while (now := time.monotonic() - start) < end_at:
        if restarted is None and now >= kill_at and server.poll() is None:
            server.send_signal(signal.SIGKILL)
            server.wait()
        if restarted is None and now >= restart_at:
            server, restarted = start_service(db, port, service_args), time.monotonic() - start
        t = time.perf_counter()
        queued = link.send(batch(i))
        spent = time.perf_counter() - t
        if restarted is not None:
            after.append(spent)
            if empty_at is None and queued <= 1:  # after the fix send() counts the batch it just queued
                empty_at = time.monotonic() - start - restarted
        i += 1
        time.sleep(max(0.0, start + i * dt - time.monotonic()))
    delivered = link.flush(60.0) and not link.pending()
    close(link)
    server.kill()
    return {"fps": fps, "outage_s": outage_s, "frames": i, "max_send_ms_after_restart": ms(max(after)),
            "frames_over_100ms_after_restart": sum(s > 0.1 for s in after),
            "median_send_ms_after_restart": ms(statistics.median(after)),
            "p99_send_ms_after_restart": ms(statistics.quantiles(after, n=100)[98]),
            "queue_empty_s_after_restart": None if empty_at is None else round(empty_at, 1),
            "all_delivered": delivered}


def parse(argv):
    p = argparse.ArgumentParser(prog="python -m experiments.edge_uplink", description=__doc__.split("\n\n")[0])
    p.add_argument("--queued", default="0,50000", help="comma list of backlog sizes for the send() figures")
    p.add_argument("--sends", type=int, default=20)
    p.add_argument("--outage-s", type=float, default=120.0, help="0: no outage measurement")
    p.add_argument("--fps", type=float, default=17.0)
    p.add_argument("--service-args", default="--no-auth", help="extra arguments of the map service")
    p.add_argument("--tag", default="after", help="record name: edge_uplink_<tag>.json")
    p.add_argument("--out", default="experiments/records/edge")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse(argv)
    service_args = args.service_args.split()
    sends = []
    for queued in (int(q) for q in args.queued.split(",") if q):
        for up in (True, False):
            if queued and up:  # a reachable server would spend this measurement draining the backlog
                continue
            with tempfile.TemporaryDirectory() as work:
                sends.append(measure_send(queued, up, args.sends, service_args, Path(work)))
                print(json.dumps(sends[-1]), flush=True)
    outage = None
    if args.outage_s > 0:
        with tempfile.TemporaryDirectory() as work:
            outage = measure_outage(args.outage_s, args.fps, service_args, Path(work))
        print(json.dumps(outage), flush=True)
    import dsfec_jax

    command = "python -m experiments.edge_uplink " + " ".join(sys.argv[1:] if argv is None else argv)
    atomic.write_json(Path(args.out) / f"edge_uplink_{args.tag}.json",
                      {"command": command, "code": str(Path(dsfec_jax.__file__).parent), "versions": versions(),
                       "send": sends, "outage": outage})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

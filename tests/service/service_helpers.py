"""Helpers shared by the map-service and uplink tests (importable like builders.py; test modules
never import each other): a real uvicorn server in a thread on a free localhost port, frame-batch
builders in the exchange format, and plain-urllib GET/POST."""

from __future__ import annotations

import copy
import json
import socket
import threading
import time
import urllib.error
import urllib.request

import uvicorn

from dsfec_jax.service.app import Access, create_app
from dsfec_jax.service.server import guarded_config
from dsfec_jax.service.store import open_store

LAT0, LON0 = 49.0069, 8.4037  # Karlsruhe, the street benchmark's origin
T0 = 1_790_000_000.0          # 2026-09-21 UTC, UNIX seconds


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


OPEN = Access(write_auth=False)  # the tests of storage and queries; test_auth.py and test_hostile.py use Access()


class LiveServer:
    """`with LiveServer(db) as srv: srv.url` - the service under uvicorn in a daemon thread (db: a
    SQLite path or a postgresql:// URL), with
    the real server's connection guards (server.guarded_config). Stops on exit; may be started
    again on the same port (an outage and a recovery). `access`: write auth off by default."""

    def __init__(self, db_path, port: int | None = None, access: Access = OPEN, header_timeout_s: float = 10.0):
        self.db_path, self.port, self.access = db_path, port or free_port(), access
        self.header_timeout_s = header_timeout_s
        self.url = f"http://127.0.0.1:{self.port}"
        self._server = self._thread = None

    def start(self) -> "LiveServer":
        config = guarded_config(create_app(self.db_path, access=self.access), "127.0.0.1", self.port,
                                header_timeout_s=self.header_timeout_s, log_level="warning")
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._server.run, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 10
        while not self._server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise RuntimeError(f"uvicorn did not start on port {self.port}")
            time.sleep(0.01)
        return self

    def stop(self) -> None:
        self._server.should_exit = True
        self._thread.join(10)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


def stored_rows(db, sql: str, args=()) -> list[tuple]:
    """The rows of a query on the service's database (a SQLite path or a postgresql:// URL)."""
    store = open_store(db)
    try:
        return [tuple(r) for r in store.snapshot_rows(sql, args)]
    finally:
        store.close()


def make_object(k: int = 0, cls: str = "car", lat: float = LAT0, lon: float = LON0) -> dict:
    """Object k of a frame, a few metres east of (lat, lon): off the ego's track."""
    return {"class": cls, "score": 0.5 + 0.05 * (k % 10), "box": [10.0 + k, 20.0, 40.0 + k, 60.0],
            "depth_m": 12.5 + k, "x_m": 2.0 + 1.5 * k, "lat": lat + 1e-5 * k, "lon": lon + 3e-5 + 2e-5 * k, "alt": 116.0}


def make_batch(i: int = 0, device: str = "dev-01", n_objects: int = 3, t: float | None = None,
               lat: float = LAT0, lon: float = LON0, classes=("car", "pedestrian", "cyclist")) -> dict:
    """Frame i of `device`: the ego at (lat, lon) + 1e-4 deg north per frame, objects just ahead."""
    ego_lat = lat + 1e-4 * i
    return {"batch_id": f"{device}:{i:06d}", "device": device, "frame": f"frame-{i:06d}",
            "time": T0 + 0.1 * i if t is None else t,
            "ego": {"lat": ego_lat, "lon": lon, "alt": 116.4, "heading_deg": 0.0},
            "objects": [make_object(k, classes[k % len(classes)], ego_lat + 1e-4, lon) for k in range(n_objects)]}


def changed(batch: dict, path: str, value) -> dict:
    """A deep copy of `batch` with the value at "objects.2.lat"-style `path` replaced (or removed
    when value is DELETE)."""
    out = copy.deepcopy(batch)
    *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    node = out
    for p in parents:
        node = node[p]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return out


class _Delete:
    def __repr__(self):  # stable across processes: pytest-xdist workers must collect the same test ids
        return "DELETE"


DELETE = _Delete()


def post(url: str, body, timeout: float = 10.0, token: str | None = None) -> tuple[int, dict]:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    headers = {"Content-Type": "application/json", **({"Authorization": f"Bearer {token}"} if token else {})}
    req = urllib.request.Request(url + "/detections", data=data, method="POST", headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}")


def get(url: str, path: str, timeout: float = 10.0, token: str | None = None) -> tuple[int, dict | str]:
    req = urllib.request.Request(url + path, headers={"Authorization": f"Bearer {token}"} if token else {})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            text = r.read().decode()
            return r.status, json.loads(text) if r.headers.get_content_type() == "application/json" else text
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}")

"""Stand-ins for the edge tests (importable like builders.py; test modules never import each other):
a fake map service that keeps batches the way the real one does, and a frame source + pipeline
cheap enough to run dsfec edge's real loop (edge.run) and real Uplink many times over."""

from __future__ import annotations

import http.server
import json
import sys
import threading
import time
from types import SimpleNamespace

from dsfec_jax.edge.frames import EdgeFrame
from dsfec_jax.edge.pipeline import FrameResult
from dsfec_jax.geo.placement import frame_batch

ORIGIN = (49.0069, 8.4037, 115.0)  # Karlsruhe, the street benchmark's origin
T0 = 1_790_000_000.0


class _QuietServer(http.server.ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request, client_address):
        if not isinstance(sys.exc_info()[1], ConnectionError):  # a killed device resets its connection
            super().handle_error(request, client_address)


class FakeMap:
    """POST /detections as the map service answers it: 201 and kept, 200 for the same id with the
    same content, 409 for other content; with `token`, 401 without `Bearer <token>`. `status`
    (when set) is answered to every POST instead, `delay_s` before each answer.
    `stored`: batch id -> body; `answers`: every status sent; `auth`: every Authorization header."""

    def __init__(self, token: str | None = None, status: int | None = None, delay_s: float = 0.0,
                 body: bytes | None = None):
        self.token, self.status, self.delay_s, self.body = token, status, delay_s, body
        self.stored: dict[str, bytes] = {}
        self.answers: list[int] = []
        self.auth: list[str | None] = []
        self.lock = threading.Lock()
        fake = self

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"  # keep-alive, as uvicorn does

            def do_POST(self):
                size = int(self.headers["Content-Length"])
                data = self.rfile.read(size)
                if len(data) < size:  # the device died mid-request
                    return
                status, reply = fake.answer(self.path, self.headers.get("Authorization"), data)
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(reply)))
                self.end_headers()
                self.wfile.write(reply)

            def log_message(self, *args):
                pass

        self.server = _QuietServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"

    def answer(self, path: str, auth: str | None, data: bytes) -> tuple[int, bytes]:
        time.sleep(self.delay_s)
        with self.lock:
            self.auth.append(auth)
            status, reply = self._decide(path, auth, data)
            self.answers.append(status)
        return status, json.dumps(reply).encode() if self.body is None or status >= 300 else self.body

    def _decide(self, path: str, auth: str | None, data: bytes) -> tuple[int, dict]:
        if self.status is not None:
            return self.status, {"detail": f"forced {self.status}"}
        if path != "/detections":
            return 404, {"detail": "Not Found"}
        if self.token is not None and auth != f"Bearer {self.token}":
            return 401, {"detail": "a valid device token is needed"}
        batch_id = json.loads(data)["batch_id"]
        if batch_id not in self.stored:
            self.stored[batch_id] = data
            return 201, {"status": "stored", "batch_id": batch_id}
        if self.stored[batch_id] == data:
            return 200, {"status": "duplicate", "batch_id": batch_id}
        return 409, {"detail": f"batch_id {batch_id!r} is stored already with different content"}

    def __enter__(self) -> "FakeMap":
        threading.Thread(target=self.server.serve_forever, args=(0.02,), daemon=True).start()
        return self

    def __exit__(self, *exc):
        self.server.shutdown()
        self.server.server_close()


def frame_ids(n: int) -> list[str]:
    return [f"{i:06d}" for i in range(n)]


def cheap_frames(n: int):
    """`frames(skip)` for edge.run: n frames at 10 Hz, no image."""
    return lambda skip: (EdgeFrame(f, 0.1 * i, None) for i, f in enumerate(frame_ids(n)) if f not in skip)


class CheapPipeline:
    """Deterministic frame batches without a detector or a depth map (frame i: the ego 1e-4 deg
    north per frame, two objects ahead), `work_s` seconds of pretended work each."""

    def __init__(self, device: str = "dev-01", work_s: float = 0.0):
        self.device, self.work_s, self.skipped = device, work_s, 0
        self.track = SimpleNamespace(origin=ORIGIN)

    def __call__(self, frame: EdgeFrame, run_id: str | None = None) -> FrameResult:
        start = time.perf_counter()
        time.sleep(self.work_s)
        i = int(frame.frame_id)
        lat = ORIGIN[0] + 1e-4 * i
        ego = {"lat": lat, "lon": ORIGIN[1], "alt": 116.4, "heading_deg": 0.0}
        objects = [{"class": "car", "score": 0.5 + 0.1 * k, "box": [10.0, 20.0, 40.0 + k, 60.0], "depth_m": 12.5 + k,
                    "x_m": 1.0 * k, "lat": lat + 1e-4, "lon": ORIGIN[1] + 2e-5 * k, "alt": 116.0} for k in range(2)]
        batch = frame_batch(self.device, frame.frame_id, T0 + frame.time_s, ego, objects, run_id)
        return FrameResult(batch, None, None, None, {"detect": time.perf_counter() - start, "depth": 0.0, "place": 0.0})

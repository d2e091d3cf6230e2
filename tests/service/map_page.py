"""Headless chromium on the map page, for the page test and the README's screenshot.

    .venv/bin/python tests/service/map_page.py --server http://127.0.0.1:8000 --out map_page.png
    .venv/bin/python tests/service/map_page.py --out map_page.png
    .venv/bin/python tests/service/map_page.py --bulk 1000000 --out big.png   # figures at 10^6 objects

The first photographs a running service's page (e.g. after `dsfec serve` and `dsfec edge
--server`: the edge pipeline's own detections). The second starts a service on a fresh database
holding the synthetic street benchmark's test drive 0 (ego poses and the ground-truth placements
of its labelled objects, posted as frame batches): what the page draws, not the detector's accuracy.
The third fills a database with N objects (bulk_fill) and prints the read endpoints' times and
sizes, the page's drawn counts, and the cost of the counts /health used to make.
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
T0 = 1_790_000_000.0  # the drive's start, UNIX seconds


def chromium(url: str, profile: Path, *args: str, budget_ms: int = 5000, timeout_s: float = 60) -> subprocess.CompletedProcess:
    """Headless chromium on `url`, kept off the network (no updates, sync, QUIC) and off the GPU;
    --virtual-time-budget lets the page's fetches and timers run before the dump / screenshot."""
    cmd = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={profile}", f"--virtual-time-budget={budget_ms}", *args, url]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=True)


def body_attributes(dom: str) -> dict[str, str]:
    """The data-* attributes of the dumped page's <body>."""
    body = re.search(r"<body([^>]*)>", dom)
    if body is None:
        raise ValueError(f"no <body> in the dumped DOM: {dom[:300]!r}")
    return dict(re.findall(r'data-([\w-]+)="([^"]*)"', body.group(1)))


def drive_batches(num_frames: int = 300, every: int = 2, device: str = "street-test-0") -> list[dict]:
    """Frame batches of the street test drive 0: the exact ego pose and every labelled object's
    ground-truth centre (WGS84 via the benchmark's pymap3d conversion), box, depth and lateral offset."""
    from dsfec_jax.data.camera.street import StreetConfig, generate_drive
    from dsfec_jax.data.camera.street.geo import enu_to_geodetic

    cfg = StreetConfig()
    drive = generate_drive(cfg, "test", 0, seed=0, num_frames=num_frames)
    batches = []
    for j in range(0, num_frames, every):
        f = drive.frame(j)
        lat, lon, alt = enu_to_geodetic(f.objects.center_enu, cfg.origin)
        objects = [{"class": str(f.boxes.names[k]), "score": round(0.5 + 0.5 * float(f.objects.visible_fraction[k]), 3),
                    "box": [float(v) for v in f.boxes.xyxy[k]], "depth_m": float(f.objects.center_cam[k, 2]),
                    "x_m": float(f.objects.center_cam[k, 0]), "lat": float(lat[k]), "lon": float(lon[k]), "alt": float(alt[k])}
                   for k in range(len(f.objects)) if f.objects.center_cam[k, 2] > 0]
        batches.append({"batch_id": f"{device}:{j:06d}", "device": device, "frame": f.frame_id,
                        "time": T0 + float(drive.times[j]),
                        "ego": {"lat": f.ego.lat, "lon": f.ego.lon, "alt": f.ego.alt,
                                "heading_deg": math.degrees(f.ego.heading_rad)},
                        "objects": objects})
    return batches


def bulk_fill(db: Path, num_objects: int, devices: int = 8, per_batch: int = 3, t0: float = T0) -> int:
    """Fill a fresh service database with `num_objects` objects, `per_batch` per frame batch,
    round-robin over `devices` driving north-east 1 m a frame, written straight into SQLite in
    the service's schema (posting 10^6 objects one batch at a time would take many minutes).
    Returns the number of batches."""
    import sqlite3

    from dsfec_jax.service.store import Store

    Store(db).close()  # creates the schema
    n_batches = -(-num_objects // per_batch)
    conn = sqlite3.connect(db)
    with conn:
        conn.execute("PRAGMA synchronous = OFF")
        batches, objects = [], []
        for i in range(n_batches):
            dev, frame = f"bulk-{i % devices:02d}", i // devices
            lat, lon = LAT0 + 9e-6 * frame + 0.001 * (i % devices), LON0 + 9e-6 * frame
            n = min(per_batch, num_objects - i * per_batch)
            t = t0 + 0.1 * frame
            batches.append((dev, f"{dev}:{frame:07d}", f"{frame:07d}", t, lat, lon, 115.0, 45.0, n, "0" * 64, t))
            objects += [(dev, f"{dev}:{frame:07d}", k, ("car", "pedestrian", "cyclist")[k % 3], 0.8,
                         lat + 1e-4, lon + 1e-4 * (k - 1), 115.0, 12.0, k - 1.0, 10.0, 20.0, 40.0, 60.0, t, f"{frame:07d}")
                        for k in range(n)]
        conn.executemany("INSERT INTO batches (device, batch_id, frame, time, ego_lat, ego_lon, ego_alt, ego_heading_deg,"
                         " n_objects, content_sha256, received) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", batches)
        conn.executemany("INSERT INTO objects (device, batch_id, idx, class, score, lat, lon, alt, depth_m, x_m, box_x1,"
                         " box_y1, box_x2, box_y2, time, frame) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                         objects)
        conn.execute("INSERT INTO devices SELECT device, COUNT(*), SUM(n_objects) FROM batches GROUP BY device")
    conn.close()
    return n_batches


LAT0, LON0 = 49.0069, 8.4037


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True, help="the PNG to write")
    p.add_argument("--server", default=None, help="photograph this running service instead of the ground-truth drive")
    p.add_argument("--frames", type=int, default=300, help="frames of the drive (10 fps)")
    p.add_argument("--every", type=int, default=2, help="post every n-th frame")
    p.add_argument("--window-size", default="1000,700")
    p.add_argument("--bulk", type=int, default=None, help="measure on a database of this many objects")
    a = p.parse_args(argv)
    if a.bulk:
        return measure_bulk(a.bulk, a.out, a.window_size)
    from dsfec_jax.core.atomic import write_bytes
    from service_helpers import LiveServer, post

    with tempfile.TemporaryDirectory() as tmp:
        shot = Path(tmp) / "map.png"
        if a.server:
            chromium(a.server.rstrip("/") + "/", Path(tmp) / "profile", f"--screenshot={shot}", f"--window-size={a.window_size}")
        else:
            with LiveServer(Path(tmp) / "map.sqlite") as srv:
                for b in drive_batches(a.frames, a.every):
                    status, reply = post(srv.url, b)
                    if status != 201:
                        raise SystemExit(f"{b['batch_id']}: HTTP {status} {reply}")
                chromium(srv.url + "/", Path(tmp) / "profile", f"--screenshot={shot}", f"--window-size={a.window_size}")
        write_bytes(a.out, shot.read_bytes())
    print(f"wrote {a.out}", file=sys.stderr)


def measure_bulk(num_objects: int, out: Path, window_size: str) -> None:
    import json
    import sqlite3
    import statistics
    import time
    import urllib.request

    from dsfec_jax.core.atomic import write_bytes
    from service_helpers import LiveServer

    def timed(url: str, repeat: int) -> tuple[float, int, dict]:
        times = []
        for _ in range(repeat):
            start = time.perf_counter()
            with urllib.request.urlopen(url, timeout=120) as r:
                body = r.read()
            times.append(time.perf_counter() - start)
        return round(1e3 * statistics.median(times), 2), len(body), json.loads(body)

    figures = {}
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "big.sqlite"
        start = time.perf_counter()
        figures["batches"] = bulk_fill(db, num_objects)
        figures["objects"] = num_objects
        figures["fill_s"] = round(time.perf_counter() - start, 1)
        with sqlite3.connect(db) as conn:  # what GET /health ran before: three counts over the tables
            start = time.perf_counter()
            [conn.execute(q).fetchone() for q in ("SELECT COUNT(*) FROM batches", "SELECT COUNT(*) FROM objects",
                                                  "SELECT COUNT(DISTINCT device) FROM batches")]
            figures["old_health_counts_ms"] = round(1e3 * (time.perf_counter() - start), 2)
        with LiveServer(db) as srv:
            for name, path, repeat in (("health", "/health", 20), ("tracks", "/tracks", 5),
                                       ("objects_5000", "/objects?limit=5000", 5)):
                ms, size, reply = timed(srv.url + path, repeat)
                figures[name] = {"median_ms": ms, "bytes": size}
                if name != "health":
                    figures[name]["cursor"] = reply["cursor"]
            for name, path in (("tracks_after_cursor", f"/tracks?after={figures['tracks']['cursor']}"),
                               ("objects_after_cursor", f"/objects?after={figures['objects_5000']['cursor']}")):
                ms, size, _ = timed(srv.url + path, 20)
                figures[name] = {"median_ms": ms, "bytes": size}
            with tempfile.TemporaryDirectory() as profile:
                start = time.perf_counter()
                dom = chromium(srv.url + "/", Path(profile), "--dump-dom", budget_ms=7000).stdout
                figures["page"] = {**body_attributes(dom), "chromium_wall_s": round(time.perf_counter() - start, 1)}
                shot = Path(profile) / "shot.png"
                chromium(srv.url + "/", Path(profile), f"--screenshot={shot}", f"--window-size={window_size}")
                write_bytes(out, shot.read_bytes())
    print(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()

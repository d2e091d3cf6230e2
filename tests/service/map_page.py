"""Headless chromium on the map page, for the page test and the README's screenshot.

    .venv/bin/python tests/service/map_page.py --server http://127.0.0.1:8000 --out map_page.png
    .venv/bin/python tests/service/map_page.py --out map_page.png

The first photographs a running service's page (e.g. after `dsfec serve` and `dsfec edge
--server`: the edge pipeline's own detections). The second starts a service on a fresh database
holding the synthetic street benchmark's test drive 0 (ego poses and the ground-truth placements
of its labelled objects, posted as frame batches): what the page draws, not the detector's accuracy.
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


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True, help="the PNG to write")
    p.add_argument("--server", default=None, help="photograph this running service instead of the ground-truth drive")
    p.add_argument("--frames", type=int, default=300, help="frames of the drive (10 fps)")
    p.add_argument("--every", type=int, default=2, help="post every n-th frame")
    p.add_argument("--window-size", default="1000,700")
    a = p.parse_args(argv)
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


if __name__ == "__main__":
    main()

"""`dsfec edge`'s loop: every frame through the pipeline, its batch kept on disk and posted.

OUT_DIR/
  batches.jsonl   one frame batch per line, appended and flushed as each frame finishes: a killed
                  run resumes after the last whole line (a torn last line is dropped), and frames
                  already there are neither recomputed nor posted again
  queue/          the uplink's disk queue (edge.uplink): batches not yet acknowledged by the server
  edge.geojson, edge.csv, edge.png   the drive's outputs (geo.export), rewritten at the end
  edge.json       the run's summary: frames, skipped, objects, per-stage times, frames/s, uplink
                  counts, the command and versions
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from ..core import atomic
from ..core.provenance import versions
from ..geo.export import write_drive_outputs
from ..geo.geodesy import enu_to_geodetic
from .pipeline import STAGES, EdgePipeline

BATCHES = "batches.jsonl"


def done_batches(out_dir: Path) -> list[dict]:
    """The whole lines of OUT_DIR/batches.jsonl; a torn last line (a kill mid-write) is cut off."""
    path = out_dir / BATCHES
    if not path.exists():
        return []
    raw = path.read_bytes()
    whole = raw[: raw.rfind(b"\n") + 1]
    if len(whole) != len(raw):
        with open(path, "r+b") as f:
            f.truncate(len(whole))
    return [json.loads(line) for line in whole.decode().splitlines() if line.strip()]


def stage_summary(seconds: list[dict]) -> dict:
    """Median and mean ms per stage, and frames/s of the whole per-frame work."""
    if not seconds:
        return {}
    out = {s: {"median_ms": round(1e3 * float(np.median([x[s] for x in seconds])), 2),
               "mean_ms": round(1e3 * float(np.mean([x[s] for x in seconds])), 2)} for s in STAGES}
    total = [sum(x[s] for s in STAGES) for x in seconds]
    out["frame"] = {"median_ms": round(1e3 * float(np.median(total)), 2), "mean_ms": round(1e3 * float(np.mean(total)), 2)}
    out["frames_per_s"] = round(1.0 / float(np.mean(total)), 2)
    return out


def truth_objects(seen: dict, origin) -> list[dict]:
    """{object id: (class, ENU)} of the synthetic drive -> the map's ground-truth markers (class,
    lat, lon, alt) at each object's last sighting."""
    if not seen:
        return []
    names, enu = zip(*seen.values())
    lat, lon, alt = enu_to_geodetic(np.asarray(enu), origin)
    return [{"class": str(n), "lat": float(a), "lon": float(o), "alt": float(h)}
            for n, a, o, h in zip(names, lat, lon, alt)]


def run_edge(frames: Callable[[frozenset], Iterable], pipeline: EdgePipeline, out_dir: str | Path,
             uplink=None, info: dict | None = None, truth_origin=None,
             progress: Callable[[int, dict], None] | None = None, flush_s: float = 30.0) -> dict:
    """Run (or resume) the edge loop; `frames(skip)` yields the EdgeFrames not in `skip`.
    truth_origin: the synthetic world's ENU origin, to draw its ground-truth objects on the map.
    Returns the summary written to edge.json."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    batches = done_batches(out_dir)
    done = frozenset(b["frame"] for b in batches)
    seconds, seen = [], {}
    with open(out_dir / BATCHES, "a") as log:
        for frame in frames(done):
            if truth_origin is not None and frame.truth is not None:
                objs = frame.truth.objects
                seen.update({int(i): (n, c) for i, n, c in zip(objs.id, frame.truth.boxes.names, objs.center_enu)})
            result = pipeline(frame)
            if result.batch is None:
                continue
            log.write(json.dumps(result.batch, allow_nan=False) + "\n")
            log.flush()
            batches.append(result.batch)
            seconds.append(result.seconds)
            if uplink is not None:
                uplink.send(result.batch)
            if progress is not None:
                progress(len(batches), result.batch)
    delivered = uplink.flush(flush_s) if uplink is not None else None
    paths = write_drive_outputs(out_dir, batches, stem="edge", truth=truth_objects(seen, truth_origin) or None,
                                origin=pipeline.track.origin)
    summary = {**(info or {}), "frames_placed": len(batches), "frames_resumed": len(done),
               "frames_skipped_no_gps": pipeline.skipped, "objects": sum(len(b["objects"]) for b in batches),
               "timing_this_run": stage_summary(seconds),
               "uplink": None if uplink is None else {**uplink.counts, "queued": len(uplink.pending()),
                                                      "delivered_all": delivered},
               "outputs": {k: str(v) for k, v in paths.items()}, "versions": versions()}
    atomic.write_json(out_dir / "edge.json", summary)
    return summary

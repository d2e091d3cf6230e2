"""`dsfec edge`'s loop: every frame through the pipeline, its batch kept on disk and posted.

OUT_DIR/
  run.json        {"run_id": ...}: a random id made when the recording run starts, in every batch
                  id ("{device}:{run_id}:{frame}"): frame ids restart with each recording, so
                  without it a second drive's batches would collide with the first's at the
                  server (409 conflicts); a resumed run reads it back, so its ids stay the same
  batches.jsonl   one frame batch per line, appended (and fsynced) as each frame finishes: a killed
                  run resumes after the last whole line (a torn last line is dropped), and frames
                  already there are neither recomputed nor posted again
  queue/          the uplink's disk queue (edge.spool): batches not yet acknowledged by the server
  edge.geojson, edge.csv, edge.png   the drive's outputs (geo.export), rewritten at the end
  edge.json       the run's summary: frames, skipped, objects, per-stage times, frames/s, uplink
                  counts, why it stopped early (if it did), the command and versions

Order of the writes, so that a kill -9 at any instant loses no frame: the batch's queue file is
made durable first, then its line is appended to batches.jsonl and fsynced, and only then may the
uplink post it. So a logged frame is always queued or at the server. Killed after the queue file
and before (or in the middle of) its line: the file is queued but the frame is not logged; the
next run appends the queued batch to the log instead of recomputing it (a recomputed batch could
differ by a rounding and meet a 409). Killed in the middle of the queue write: the uplink removes
the temporary file at start and the frame, never logged, is computed again.
"""

from __future__ import annotations

import json
import os
import re
import secrets
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from ..core import atomic
from ..core.provenance import versions
from ..geo.export import write_drive_outputs
from ..geo.geodesy import enu_to_geodetic
from .pipeline import STAGES, EdgePipeline
from .spool import SpoolFull, batch_id_of, read_queued

BATCHES = "batches.jsonl"
RUN = "run.json"
_RUN_ID = re.compile(r"^[0-9a-f]{12}$")


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
    return [_batch_line(path, n, line) for n, line in enumerate(whole.splitlines(), 1) if line.strip()]


def _batch_line(path: Path, number: int, line: bytes) -> dict:
    try:
        batch = json.loads(line)
    except ValueError as e:
        raise ValueError(f"{path} line {number}: not a frame batch ({e}); a whole line is never torn by a kill, "
                         f"so the file was changed by hand: fix or remove that line") from None
    if not isinstance(batch, dict) or not isinstance(batch.get("batch_id"), str) or "frame" not in batch:
        raise ValueError(f"{path} line {number}: expected a frame batch with batch_id and frame")
    return batch


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


def remove_temporaries(out_dir: Path) -> None:
    """Atomic writes of run.json or the outputs that a kill interrupted before their rename."""
    for path in out_dir.iterdir():
        if atomic.is_temporary(path.name) and path.is_file():
            path.unlink()


def run_id(out_dir: Path, recording: dict | None = None) -> str:
    """OUT_DIR/run.json's run id, made (random, 12 hex digits) and written atomically on first use,
    with `recording` (what is being recorded: device, source). A resume must record the same thing:
    frame ids restart with each recording, so resuming drive 0's folder for drive 1 (or as another
    device) would skip frames that were never computed; that is a ValueError naming the field."""
    path = out_dir / RUN
    if not path.exists():
        atomic.write_json(path, {"run_id": secrets.token_hex(6), "recording": recording or {}})
    try:
        stored = json.loads(path.read_bytes()[:65536])
        value = stored["run_id"]
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{path}: expected {{\"run_id\": \"<12 hex digits>\"}} ({e})") from None
    if not isinstance(value, str) or not _RUN_ID.match(value):
        raise ValueError(f"{path}: run_id {value!r} is not 12 hex digits")
    was = stored.get("recording") or {}
    for key, now in (recording or {}).items():
        if key in was and was[key] != now:
            raise ValueError(f"{path}: recording.{key} is {was[key]!r}, this run records {now!r}; "
                             f"resume with the same settings or choose another --out")
    return value


def append_line(log, batch: dict) -> None:
    """One batch as one line, on disk before the uplink may post it (see the module's docstring)."""
    log.write(json.dumps(batch, allow_nan=False) + "\n")
    log.flush()
    os.fsync(log.fileno())


def keep(batch: dict, log, uplink) -> None:
    """A finished frame's batch: queued durably, then logged, then posted (see the module's docstring)."""
    if uplink is None:
        append_line(log, batch)
    else:
        uplink.send(batch, on_spooled=lambda queued: append_line(log, queued))


def recover_queued(uplink, logged: list[dict], log) -> list[dict]:
    """The batches a killed run queued but did not log (killed between the two writes): appended to
    the log now, in queue order, so the frames count as done and are not recomputed."""
    ids = {b["batch_id"] for b in logged}
    recovered = [read_queued(p) for p in uplink.pending() if batch_id_of(p) not in ids]
    for batch in recovered:
        append_line(log, batch)
    return recovered


def run_edge(frames: Callable[[frozenset], Iterable], pipeline: EdgePipeline, out_dir: str | Path,
             uplink=None, info: dict | None = None, truth_origin=None,
             progress: Callable[[int, dict], None] | None = None, flush_s: float = 30.0,
             recording: dict | None = None) -> dict:
    """Run (or resume) the edge loop; `frames(skip)` yields the EdgeFrames not in `skip`.
    truth_origin: the synthetic world's ENU origin, to draw its ground-truth objects on the map.
    The loop stops early, with the reason in the summary's "stopped", when the uplink meets a fatal
    answer (a wrong URL or token) or its queue is full; every frame done so far stays logged and
    queued. `recording` (e.g. device and source) must match the out dir's on a resume (run_id).
    Returns the summary written to edge.json."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    remove_temporaries(out_dir)
    this_run = run_id(out_dir, recording)
    batches = done_batches(out_dir)
    seconds, seen, stopped = [], {}, None
    with open(out_dir / BATCHES, "a") as log:
        if uplink is not None:
            batches += recover_queued(uplink, batches, log)
        done = frozenset(b["frame"] for b in batches)
        for frame in frames(done):
            if truth_origin is not None and frame.truth is not None:
                objs = frame.truth.objects
                seen.update({int(i): (n, c) for i, n, c in zip(objs.id, frame.truth.boxes.names, objs.center_enu)})
            result = pipeline(frame, this_run)
            if result.batch is None:
                continue
            try:
                keep(result.batch, log, uplink)
            except SpoolFull as e:
                stopped = f"{e}; stopped before frame {frame.frame_id}, which the next run computes"
                break
            batches.append(result.batch)
            seconds.append(result.seconds)
            if progress is not None:
                progress(len(batches), result.batch)
            if uplink is not None and uplink.fatal:
                stopped = f"{uplink.fatal}; stopped after frame {frame.frame_id}"
                break
    uplink_summary = None
    if uplink is not None:
        uplink.flush(flush_s)
        uplink.close()
        uplink_summary = uplink.summary()
    paths = write_drive_outputs(out_dir, batches, stem="edge", truth=truth_objects(seen, truth_origin) or None,
                                origin=pipeline.track.origin)
    summary = {**(info or {}), "run_id": this_run, "frames_placed": len(batches), "frames_resumed": len(done),
               "frames_skipped_no_gps": pipeline.skipped, "objects": sum(len(b["objects"]) for b in batches),
               "stopped": stopped, "timing_this_run": stage_summary(seconds), "uplink": uplink_summary,
               "outputs": {k: str(v) for k, v in paths.items()}, "versions": versions()}
    atomic.write_json(out_dir / "edge.json", summary)
    return summary

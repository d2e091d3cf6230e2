"""Issue 25's measured tables on the synthetic test drive: depth error per detection and
localisation error of placed objects by range, beside the paper's claim, and the edge pipeline's
frames/s at one thread.

    python -m experiments.edge_errors [--frames 300] [--drive 0] [--seed 0] [--threads 1]
                                      [--depth-weights W] [--out experiments/records/edge]

One drive of the street benchmark's test split (10 Hz frames, 1 Hz GPS fixes). The shipped
Shuffle-YOLOv3 detects (score >= 0.3); each detection is matched to a ground-truth box (IoU >= 0.5,
same class; metrics/localisation.match_frame) and only matched detections are scored.

- Depth error per detection: the monodepth network's depth at the box's reference point against
  the same reading (geo.placement.sample_at, the same window) of the exact depth map: what the
  depth estimate costs, for both reference points. Bins are of that true depth.
- Localisation error: the horizontal distance from the placed position to the object's true
  3D centre, by the object's true range (its centre's depth along the optical axis). Rows separate
  the sources of error: exact depth + exact pose (only the reference point: a box's centre sees
  the object's near surface, about half its length in front of its centre), exact depth + the
  1 Hz GPS interpolated (+ heading from the track), and the network's depth + GPS (the system).
- Frames/s: the per-frame work of `dsfec edge` (detector, network depth, placement) at --threads,
  median over the drive after the first (compiling) frame.

Writes edge_errors.md and edge_errors.json (tables, command, seed, versions) atomically to --out.
The figures are synthetic: rendered frames, exact ground truth.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import sys
import time
from pathlib import Path

import numpy as np

RANGE_NOTE = "paper §4.3 / §5: the depth error within 40 m does not exceed 5 %"
SCORE = 0.3


def parse(argv=None):
    p = argparse.ArgumentParser(prog="python -m experiments.edge_errors")
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--drive", type=int, default=0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--depth-weights", default=None)
    p.add_argument("--out", default="experiments/records/edge")
    return p.parse_args(argv)


class Collector:
    """Per-detection rows of one (depth source, pose, reference point) configuration."""

    def __init__(self):
        self.pred_depth, self.true_depth, self.errors, self.ranges = [], [], [], []

    def add(self, pred_depth, true_depth, errors, ranges):
        for store, values in zip((self.pred_depth, self.true_depth, self.errors, self.ranges),
                                 (pred_depth, true_depth, errors, ranges)):
            store.extend(np.asarray(values, np.float64).tolist())


def frame_rows(frame, dets, pairs, depth_maps, ego_states, collectors, references):
    from dsfec_jax.geo.placement import Placer, lateral_offset, place_enu
    from dsfec_jax.metrics.localisation import horizontal_errors

    di, gi = pairs[:, 0], pairs[:, 1]
    xyxy = dets.xyxy[di]
    truth_centre = frame.objects.center_enu[gi]
    true_range = frame.objects.center_cam[gi, 2]
    for ref in references:
        placer = Placer(fx=frame.camera.fx, cx=frame.camera.cx, origin=(0.0, 0.0, 0.0), reference=ref)
        true_d, u = placer.depths(xyxy, depth_maps["truth"])
        for (source, pose), coll in collectors[ref].items():
            d = true_d if source == "truth" else placer.depths(xyxy, depth_maps[source])[0]
            enu, heading = ego_states[pose]
            ok = np.isfinite(d) & (d > 0) & np.isfinite(true_d) & (true_d > 0)
            placed = place_enu(d[ok], lateral_offset(u[ok], d[ok], frame.camera.cx, frame.camera.fx), enu, heading)
            coll.add(d[ok], true_d[ok], horizontal_errors(placed, truth_centre[ok]), true_range[ok])


def measure(args) -> dict:
    from dsfec_jax import api, zoo
    from dsfec_jax.cli_edge import DEPTH_MODEL
    from dsfec_jax.data.camera.street import StreetConfig, generate_drive
    from dsfec_jax.edge.depth_sources import NetworkDepth
    from dsfec_jax.edge.frames import drive_frames
    from dsfec_jax.geo.gps import EgoTrack, GpsFixes, clean_fixes
    from dsfec_jax.geo.placement import REFERENCE_POINTS, Placer
    from dsfec_jax.metrics.localisation import match_frame
    from dsfec_jax.modalities.image.depth import load_depth_predictor

    cfg = StreetConfig()
    drive = generate_drive(cfg, "test", args.drive, args.seed, args.frames)
    detect = api.load("shuffle_yolov3", predictor_options={"score_threshold": SCORE})
    network = NetworkDepth(load_depth_predictor(args.depth_weights or zoo.shipped_weights(DEPTH_MODEL)), cfg.baseline_m)
    fixes, report = clean_fixes(GpsFixes.from_track(drive.gps, source="drive GPS"))
    track = EgoTrack(fixes, origin=cfg.origin)  # the world's ENU frame, so truth and placement compare directly
    camera = cfg.camera_model()
    configs = (("truth", "exact"), ("truth", "gps"), ("network", "gps"))
    collectors = {ref: {c: Collector() for c in configs} for ref in REFERENCE_POINTS}
    stage_s, detections, matched = [], 0, 0
    placer = Placer(fx=camera.fx, cx=camera.cx, origin=cfg.origin)
    for j, edge_frame in enumerate(drive_frames(drive)):
        frame = edge_frame.truth
        t0 = time.perf_counter()
        dets = detect(frame.image)
        t1 = time.perf_counter()
        depth_maps = {"truth": np.asarray(frame.depth, np.float64), "network": network(edge_frame, camera)}
        t2 = time.perf_counter()
        ego = track.state(edge_frame.time_s)
        placer.place(dets.xyxy, dets.names, dets.scores, depth_maps["network"], ego.enu, ego.heading_rad)
        t3 = time.perf_counter()
        if j:  # the first frame compiles
            stage_s.append((t1 - t0, t2 - t1, t3 - t2))
        pairs = match_frame(frame.boxes.xyxy, frame.boxes.names, dets.xyxy, dets.names, dets.scores)
        detections, matched = detections + len(dets), matched + len(pairs)
        if len(pairs):
            exact = (np.asarray(frame.ego.enu), frame.ego.heading_rad)
            frame_rows(frame, dets, pairs, depth_maps, {"exact": exact, "gps": (np.asarray(ego.enu), ego.heading_rad)},
                       collectors, REFERENCE_POINTS)
    return dict(collectors=collectors, stage_s=np.asarray(stage_s), detections=detections, matched=matched,
                gps=report.to_dict(), frames=len(drive))


def tables(result: dict) -> tuple[str, dict]:
    from dsfec_jax.metrics.depth.per_detection import depth_error_table, format_depth_table
    from dsfec_jax.metrics.localisation import format_localisation_table, localisation_table

    md, record = [], {"depth": {}, "localisation": {}}
    for ref, colls in result["collectors"].items():
        net = colls[("network", "gps")]
        rows = depth_error_table(net.pred_depth, net.true_depth)
        record["depth"][ref] = [r.to_dict() for r in rows]
        md += [f"### Depth error per detection, network, reference point {ref} ({RANGE_NOTE})", "",
               format_depth_table(rows)]
        for (source, pose), coll in colls.items():
            rows = localisation_table(coll.errors, coll.ranges)
            record["localisation"][f"{ref}/{source}-depth/{pose}-pose"] = [r.to_dict() for r in rows]
            md += [f"### Localisation error, reference {ref}, {source} depth, {pose} pose", "",
                   format_localisation_table(rows)]
    s = result["stage_s"]
    timing = {k: round(1e3 * float(np.median(s[:, i])), 2) for i, k in enumerate(("detect_ms", "depth_ms", "place_ms"))}
    timing["frame_ms"] = round(1e3 * float(np.median(s.sum(1))), 2)
    timing["frames_per_s"] = round(1e3 / timing["frame_ms"], 2)
    record["timing"] = timing
    md += ["### Edge pipeline per frame (median ms)", "",
           "| detect | depth | place | frame | frames/s |", "|---|---|---|---|---|",
           f"| {timing['detect_ms']} | {timing['depth_ms']} | {timing['place_ms']} | {timing['frame_ms']} | "
           f"{timing['frames_per_s']} |", ""]
    return "\n".join(md), record


def main(argv=None) -> int:
    args = parse(argv)
    if args.threads:
        from dsfec_jax.core import threads

        threads.pin(args.threads)
    from dsfec_jax.core import atomic
    from dsfec_jax.core.provenance import versions

    result = measure(args)
    md, record = tables(result)
    head = (f"Synthetic street test drive {args.drive} (seed {args.seed}): {result['frames']} frames, "
            f"{result['detections']} detections (score >= {SCORE}), {result['matched']} matched to ground truth.\n\n")
    out = Path(args.out)
    command = "python -m experiments.edge_errors " + " ".join(sys.argv[1:] if argv is None else argv)
    atomic.write_text(out / "edge_errors.md", head + md)
    atomic.write_json(out / "edge_errors.json", {"command": command, "seed": args.seed, "threads": args.threads,
                                                 "frames": result["frames"], "detections": result["detections"],
                                                 "matched": result["matched"], "gps": result["gps"],
                                                 "versions": versions(), **record})
    print(head + md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

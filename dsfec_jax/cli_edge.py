"""`dsfec edge | serve | depth`: the paper's edge-to-server system (Fig. 2) and its depth network.

    dsfec edge  --out runs/edge/drive0 [--drive-frames 300 --seed 0]            # the synthetic test drive
    dsfec edge  --frames DIR --gps gps.csv --out OUT [--server http://127.0.0.1:8000] [--device cam-01]
                [--token-file PATH]                                           # or $DSFEC_MAP_TOKEN
    dsfec serve --db runs/map.sqlite [--host 127.0.0.1 --port 8000]          # + `dsfec serve token add ...`
    dsfec depth train --run-dir runs/depth/monodepth_street --steps 1500 --frames 2000
    dsfec depth eval  [--weights PATH] --frames 50
    dsfec depth ship  --run-dir RUN [--out PATH]      # weights + manifest: training record, measured figures
    dsfec depth convert --weights OLD [--out PATH]    # a file of the depth weights' first format -> the zoo's

`dsfec edge` runs detector -> depth -> placement on every frame (edge.pipeline), appends each frame's
batch to OUT/batches.jsonl (a killed run resumes), posts it to --server through a disk queue
(edge.uplink: an unreachable server loses nothing), and writes OUT/edge.geojson, edge.csv, edge.png
and edge.json (per-stage times, frames/s, uplink counts). It exits non-zero, saying why, when a
batch was not delivered: still queued, rejected, a conflict, or a fatal answer (a wrong --server or
token: the run stops at once and keeps its batches queued for the next run). Without --frames it
runs the street benchmark's synthetic drive, whose GPS fixes it uses unless --gps is given.
--depth: network (the shipped monodepth weights, or --depth-weights), truth (the synthetic drive's
exact depth), stereo:DIR (your disparity maps in pixels) or depth:DIR (your depth maps in metres),
one <frame>.npy or 16-bit <frame>.png per frame. --a: the paper's adjustment coefficient in
depth = b f / (a d) for the network's disparity d (a fraction of the width; default a = the image
width, so a d is in pixels).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .argtypes import add_parallel_flags, command_line, positive_int
from .service.options import add_arguments as add_service_arguments

EDGE_COMMANDS = ("edge", "serve", "depth")
TOKEN_ENV = "DSFEC_MAP_TOKEN"
DEPTH_MODEL = "monodepth_street"  # the zoo's auxiliary variant whose shipped weights `--depth network` runs


def add_commands(sub) -> None:
    e = sub.add_parser("edge", help="detector + monocular depth + GPS placement over frames; post to a map server")
    e.add_argument("--frames", default=None, help="a folder of frames (times.csv, camera.json); default: the synthetic drive")
    e.add_argument("--gps", default=None, help="GPS fixes, CSV time_s,lat,lon,alt or JSON (default: the drive's)")
    e.add_argument("--fps", type=float, default=None, help="--frames without times.csv: the frame rate")
    e.add_argument("--out", required=True, help="output folder (resumed if it holds a run)")
    e.add_argument("--server", default=None, help="map service URL, e.g. http://127.0.0.1:8000")
    e.add_argument("--device", default="edge-01")
    e.add_argument("--token-file", default=None,
                   help=f"file whose first line is this device's write token (default: ${TOKEN_ENV}, if set)")
    e.add_argument("--max-queued", type=positive_int, default=100_000,
                   help="batches the disk queue may hold while the server is away; at the cap the run stops "
                        "(nothing is dropped; a rerun resumes)")
    e.add_argument("--model", default="shuffle_yolov3")
    e.add_argument("--weights", default=None, help="detector weights (default: shipped)")
    e.add_argument("--score-threshold", type=float, default=0.3, help="detections kept for placement")
    e.add_argument("--depth", default="network", help="network | truth | stereo:DIR | depth:DIR")
    e.add_argument("--depth-weights", default=None, help=f"monodepth weights (default the shipped {DEPTH_MODEL})")
    e.add_argument("--a", type=float, default=None, help="adjustment coefficient a in depth = b f / (a d)")
    e.add_argument("--baseline", type=float, default=None, help="stereo baseline b in metres (default: camera.json / 0.54)")
    e.add_argument("--reference", default="center", choices=("center", "bottom_center"))
    e.add_argument("--strict-gps", action="store_true", help="a bad GPS fix is an error (default: skipped and counted)")
    e.add_argument("--threads", type=positive_int, default=None, help="pin to this many CPU threads")
    e.add_argument("--drive-frames", type=positive_int, default=300, help="synthetic drive: frames (10 Hz)")
    e.add_argument("--drive", type=int, default=0, help="synthetic drive: index in the test split")
    e.add_argument("--seed", type=int, default=0)
    s = sub.add_parser("serve", help="the map service: POST /detections, GET /objects, GET / (map page); token admin")
    add_service_arguments(s)
    d = sub.add_parser("depth", help="train, evaluate or ship the monodepth network on the street benchmark")
    d.add_argument("action", choices=("train", "eval", "ship", "convert"))
    d.add_argument("--run-dir", default=None, help="train: the run directory (resumed if it exists); ship: the finished run")
    d.add_argument("--out", default=None, help=f"ship, convert: where the weights go (default the shipped {DEPTH_MODEL}'s)")
    d.add_argument("--steps", type=positive_int, default=1500)
    d.add_argument("--frames", type=positive_int, default=None, help="train: rendered stereo pairs (2000); eval, ship, convert: test frames measured (50)")
    d.add_argument("--batch-size", type=positive_int, default=8)
    d.add_argument("--input", default=None, metavar="HxW", help="train: network input size (default the config's, 128x224)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--weights", default=None,
                   help=f"eval: weights (default the shipped {DEPTH_MODEL}); convert: the file to convert")
    d.add_argument("--init", default=None, metavar="PATH",
                   help="train: start from these weights or checkpoint (same --input): continue or fine-tune")
    d.add_argument("--json", action="store_true")
    add_parallel_flags(d)


def main(args) -> int:
    if getattr(args, "threads", None):
        from .core import threads

        threads.pin(args.threads)  # before XLA starts
    if args.command == "serve":
        from .service.options import run

        return run(args, "dsfec serve")
    if args.command == "depth":
        return run_depth(args)
    return run_edge_command(args)


def run_depth(args) -> int:
    import json

    from . import zoo

    if args.action == "train":
        from .modalities.image.fit_depth import fit_depth

        if not args.run_dir:
            sys.exit("dsfec depth train: --run-dir is required")
        try:
            size = dict(zip(("height", "width"), map(int, args.input.lower().split("x")))) if args.input else {}
            config = zoo.config(DEPTH_MODEL, **size)
        except ValueError as err:
            sys.exit(f"dsfec depth train: --input {args.input!r}: {err} (expected HxW, multiples of 32)")
        try:
            _, info = fit_depth(args.run_dir, config, args.frames or 2000, args.steps, args.batch_size, args.seed,
                                init=args.init, command=command_line(args))
        except (OSError, ValueError) as err:
            sys.exit(f"dsfec depth train: {err}")
        print(json.dumps({k: v for k, v in info.items() if k != "losses"}, indent=1))
        return 0
    if args.action in ("ship", "convert"):
        return ship_depth(args)
    from .data.camera.street import StreetConfig, StreetDataset
    from .modalities.image.depth import load_depth_predictor
    from .modalities.image.fit_depth import evaluate_dense

    from .core.progress import FIRST_BATCH, bar

    predictor = load_depth_predictor(args.weights or zoo.shipped_weights(DEPTH_MODEL))
    frames = StreetDataset(StreetConfig(), "test", args.seed, args.frames or 50)
    scores = evaluate_dense(predictor, bar(frames, "depth eval (street test frames)", first=FIRST_BATCH,
                                           total=len(frames)))
    print(json.dumps(scores, indent=1) if args.json else "  ".join(f"{k} {v:.4f}" for k, v in scores.items()))
    return 0


def ship_depth(args) -> int:
    """`dsfec depth ship` (a finished run) or `dsfec depth convert` (a first-format file): the
    weights with the detectors' manifest rules (modalities/image/ship_depth.py)."""
    import json

    from . import zoo
    from .modalities.image import ship_depth as sd

    source = args.run_dir if args.action == "ship" else args.weights
    if not source:
        sys.exit(f"dsfec depth {args.action}: --{'run-dir' if args.action == 'ship' else 'weights'} is required")
    ship = sd.ship_depth_weights if args.action == "ship" else sd.convert_depth_weights
    try:
        manifest = ship(source, args.out or zoo.shipped_weights(DEPTH_MODEL), command_line(args),
                        args.frames or sd.MEASURED_FRAMES)
    except (OSError, ValueError) as err:
        sys.exit(f"dsfec depth {args.action}: {err}")
    shown = {"step": manifest["step"], "train_command": manifest["training"].get("command"),
             "measured": manifest["measured"], "sha256": manifest["sha256"]}
    print(json.dumps(shown, indent=1))
    return 0


def depth_source(args, baseline_m: float):
    from .edge import depth_sources as ds

    kind, _, where = args.depth.partition(":")
    if kind == "network":
        from . import zoo
        from .modalities.image.depth import load_depth_predictor

        weights = args.depth_weights or zoo.shipped_weights(DEPTH_MODEL)
        return ds.NetworkDepth(load_depth_predictor(weights), baseline_m, args.a)
    if kind == "truth":
        return ds.TruthDepth()
    if kind in ("stereo", "depth") and where:
        return ds.StereoDisparityFiles(where, baseline_m) if kind == "stereo" else ds.DepthFiles(where)
    sys.exit(f"dsfec edge: --depth {args.depth!r}; expected network, truth, stereo:DIR or depth:DIR")


def gps_track(args, drive_gps=None):
    from .geo.gps import EgoTrack, GpsFixes, clean_fixes, read_gps

    fixes = read_gps(args.gps) if args.gps else GpsFixes.from_track(drive_gps, source="the synthetic drive's GPS")
    fixes, report = clean_fixes(fixes, strict=args.strict_gps)
    if report.num_skipped:
        print(f"dsfec edge: {report}", file=sys.stderr)
    return EgoTrack(fixes), report


def run_edge_command(args) -> int:
    from . import api
    from .edge.frames import drive_frames, folder_frames
    from .edge.pipeline import EdgePipeline
    from .edge.run import run_edge

    info = {"command": command_line(args), "seed": args.seed}
    try:
        if args.frames:
            folder = folder_frames(args.frames, args.fps)
            camera, baseline, frames, offset, truth_origin = folder.camera, folder.baseline_m, folder.frames, 0.0, None
            if not args.gps:
                sys.exit("dsfec edge: --frames needs --gps FILE (CSV time_s,lat,lon,alt on the frames' clock)")
            track, report = gps_track(args)
        else:
            drive, camera, baseline, offset = synthetic_drive(args)
            frames, truth_origin = (lambda skip: drive_frames(drive, skip)), drive.cfg.origin
            track, report = gps_track(args, drive.gps)
            info["drive"] = {"split": "test", "index": args.drive, "seed": args.seed, "frames": args.drive_frames}
        depth = depth_source(args, args.baseline or baseline or 0.54)
        detect = api.load(args.model, weights=args.weights,
                          predictor_options={"score_threshold": args.score_threshold})
    except (FileNotFoundError, ValueError) as err:
        sys.exit(f"dsfec edge: {err}")
    info.update(gps=report.to_dict(), depth=args.depth, reference=args.reference, model=args.model)
    pipeline = EdgePipeline(detect, depth, camera, track, args.device, args.reference, offset)
    uplink = None
    if args.server:
        from .edge.uplink import Uplink

        try:
            uplink = Uplink(args.server, Path(args.out) / "queue", token=read_token(args), max_queued=args.max_queued)
        except (OSError, ValueError) as err:
            sys.exit(f"dsfec edge: {err}")
    from tqdm import tqdm

    from .core.progress import quiet

    try:
        recording = {"device": args.device,
                     "source": str(Path(args.frames).resolve()) if args.frames else info["drive"]}
        # stderr; the first frame compiles
        with tqdm(desc="edge frames placed", unit="frame", disable=quiet()) as bar:
            summary = run_edge(frames, pipeline, args.out, uplink, info, truth_origin, recording=recording,
                               progress=lambda done, batch: bar.update(1))
    except ValueError as err:  # a batches.jsonl, run.json or queued file changed by hand; a bad depth file
        sys.exit(f"dsfec edge: {err}")
    timing = summary["timing_this_run"]
    print(f"{summary['frames_placed']} frames ({summary['frames_resumed']} resumed, "
          f"{summary['frames_skipped_no_gps']} without GPS), {summary['objects']} objects placed; "
          f"{timing.get('frames_per_s', '-')} frames/s; outputs in {args.out}")
    return uplink_report(summary, Path(args.out) / "queue")


def read_token(args) -> str | None:
    """--token-file's first line, else $DSFEC_MAP_TOKEN, else None (a server run with --no-auth)."""
    if args.token_file is None:
        return os.environ.get(TOKEN_ENV, "").strip() or None
    path = Path(args.token_file)
    with open(path, "rb") as f:
        first = f.read(8192).split(b"\n", 1)[0].strip()
    if not first:
        raise ValueError(f"--token-file {path}: its first line is empty (expected the device's token)")
    if path.stat().st_mode & 0o077:
        print(f"dsfec edge: warning: {path} is readable by others (chmod 600 {path})", file=sys.stderr)
    return first.decode("ascii", "replace")


def uplink_report(summary: dict, queue: Path) -> int:
    """Print what the uplink delivered and what it did not; 0 only when every batch arrived."""
    up = summary["uplink"]
    if up is None:
        return 0
    print(f"uplink: {up['sent']} stored, {up['duplicate']} duplicates, {up['rejected']} rejected, "
          f"{up['conflicts']} conflicts, {up['retried']} failed attempts retried, {up['queued']} still queued")
    problems = []
    if summary["stopped"]:
        problems.append(summary["stopped"])
    if up["queued"]:
        problems.append(f"{up['queued']} batches still queued in {queue} (the next run sends them first)")
    for kind, why in (("rejected", "the server refused them (reasons beside them)"),
                      ("conflicts", "their ids are stored with other content")):
        if up[f"{kind}_total"]:
            problems.append(f"{up[f'{kind}_total']} batches in {queue / kind}: {why}")
    if problems:
        sys.exit("dsfec edge: not everything was delivered:\n  " + "\n  ".join(problems))
    return 0


def synthetic_drive(args):
    from .data.camera.street import StreetConfig, generate_drive
    from .edge.frames import DRIVE_EPOCH_S

    from .core import progress

    cfg = StreetConfig()
    with progress.stage(f"rendering synthetic drive {args.drive} ({args.drive_frames} frames)"):
        drive = generate_drive(cfg, "test", args.drive, args.seed, args.drive_frames)
    return drive, cfg.camera_model(), cfg.baseline_m, DRIVE_EPOCH_S

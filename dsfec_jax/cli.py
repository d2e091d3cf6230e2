"""`dsfec train | eval | predict | ship | export | quantize | bench | edge | serve | depth` (also
`python -m dsfec_jax ...`; the last three: cli_edge):
thin commands over the library, the same flags for every family.

    dsfec train   --model dsfec_s [--set stem_filters=16] [--data synthetic] [--schedule quick] --run-dir runs/s
    dsfec eval    --model dsfec_s [--weights PATH] --data synthetic --split test --seed 0 --frames 200 --json
    dsfec predict --model dsfec_s [--weights PATH] --data tj4d:PATH --split all --out pred.json [--png-dir DIR]
    dsfec train   --model yolov8n [--data synthetic] [--schedule quick] --run-dir runs/v8n
    dsfec predict --model yolov8n --weights runs/v8n/checkpoints/best --out dets.json --gt-out gt.json --png-dir png
    dsfec train   --model shuffle_yolov3 --data street --schedule quick --run-dir runs/sy3 [--steps N]
    dsfec eval    --model shuffle_yolov3 --weights runs/sy3/checkpoints/best --data voc:DIR --split all
    dsfec export  --model shuffle_yolov3 --weights runs/sy3/checkpoints/best --out exports/sy3 [--size 416]
    dsfec predict --model shuffle_yolov3 --input photos/ "more/*.jpg" --out dets.json --png-dir png   # your own files

Each command resolves the model's config once (--model, --set and the fields the modality's flags
or data decide), then hands it to the verb of the config's Modality record (modalities/registry):
modalities/<points|rd|image>/cli.py, where their readings of the shared flags are documented.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path

from .argtypes import add_parallel_flags, command_line, non_negative_int, positive_int
from .cli_edge import EDGE_COMMANDS, add_commands as add_edge_commands
from .core.defaults import POINT_SCORE_THRESHOLD, RUN_PILLARS

INFER_BENCH_MODELS = "baseline,dsfec_l,dsfec_m,dsfec_s"
TRAIN_BENCH_MODELS = "dsfec_s,dsfec_l,radarnext_fpn"  # the issue-20 acceptance models; 'all' for every variant


def parse_overrides(items: list[str]) -> dict:
    """`field=value` pairs; values are Python literals where they parse (3, (1,3,3,2), 'relu')."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item!r}: expected FIELD=VALUE")
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[key] = value
    return out


def common(p: argparse.ArgumentParser, split: str) -> None:
    p.add_argument("--model", required=True, help="a zoo name (dsfec_jax.zoo.available())")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="config override")
    p.add_argument("--data", default="synthetic",
                   help="synthetic (the family's embedded benchmark) | points: synthetic4d | vod:PATH | tj4d:PATH | "
                        "nuscenes:DATAROOT; range-Doppler: synthetic:v1 (the benchmark before issue 54) | raddet:PATH | "
                        "carrada:PATH; camera: street | street:DIR | voc:DIR")
    p.add_argument("--split", default=split)
    p.add_argument("--frames", type=positive_int, default=None,
                   help="frames (RD models: samples) to use (synthetic: to generate)")
    p.add_argument("--seed", type=int, default=0, help="data seed (synthetic) and init seed (train)")
    p.add_argument("--max-pillars", type=positive_int, default=None,
                   help=f"point models: pillar slots (default {RUN_PILLARS})")
    p.add_argument("--size", type=positive_int, default=None,
                   help="camera models: the long side each image is letterboxed to for evaluation and prediction "
                        "(a multiple of 32; default 416)")


def start_parallel(args) -> None:
    """--devices and --coordinator (commands that train) take effect before anything runs JAX."""
    from .train import parallel

    if hasattr(args, "devices"):
        parallel.start_or_exit(args, f"dsfec {args.command}")


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="dsfec", description="train, evaluate and run zoo detectors")
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train a zoo model (resumes an existing run directory)")
    common(t, "train")
    t.add_argument("--run-dir", required=True)
    t.add_argument("--schedule", default="quick",
                   help="quick | paper: the family's profile (points: quick / paper; range-Doppler: yolo_quick / "
                        "yolo_paper), or any train.schedules preset (radarnext, yolo_quick, yolo_paper, ...)")
    t.add_argument("--steps", type=positive_int, default=None, help="override the schedule's length")
    t.add_argument("--batch-size", type=positive_int, default=None)
    t.add_argument("--decay-at", default=None, metavar="F1,F2",
                   help="fractions of training where the rate drops x0.1 (default: the schedule's)")
    t.add_argument("--val-frames", type=positive_int, default=100)
    t.add_argument("--eval-every", type=non_negative_int, default=200, help="validate every N steps (0: at the end only)")
    t.add_argument("--no-augment", action="store_true")
    t.add_argument("--ema", action=argparse.BooleanOptionalAction, default=None,
                   help="validate and ship an exponential moving average of the weights, as ultralytics trains "
                        "(default: on for the range-Doppler YOLO and camera models, off for the point-cloud ones)")
    t.add_argument("--no-tensorboard", action="store_true",
                   help="write no TensorBoard event files into the run directory (they sit beside metrics.jsonl)")
    t.add_argument("--window", type=non_negative_int, default=None,
                   help="point models: train on overlapping WxW-cell windows of the grid (default 96; 0 = the whole grid)")
    t.add_argument("--sizes", default=None, metavar="LOW,HIGH",
                   help="camera models: multi-scale input sizes (long side; every multiple of 32 from LOW to HIGH, "
                        "or one SIZE); default the profile's (quick 320,416; paper 320,608)")
    t.add_argument("--window-sampling", default=None, choices=("cycle", "objects"),
                   help="point models: cycle the windows (default), or favour windows holding a box "
                        "(80 %% of steps; sparse scenes)")
    add_parallel_flags(t)
    sh = sub.add_parser("ship", help="package a trained run's weights into dsfec_jax/weights with a manifest")
    sh.add_argument("--model", required=True)
    sh.add_argument("--run-dir", required=True)
    sh.add_argument("--checkpoint", default="best", choices=("best", "last"))
    sh.add_argument("--frames", type=positive_int, default=200, help="val and test frames of the family's synthetic benchmark to measure")
    sh.add_argument("--out-dir", default=None, help="default: the package's weights directory")
    ex = sub.add_parser("export", help="ONNX + jax.export of the network with box decoding (NMS stays on the host)")
    ex.add_argument("--model", required=True)
    ex.add_argument("--weights", default=None, help="weights file or training checkpoint (RUN/checkpoints/best, RUN/checkpoints/last/step_N; default: shipped weights)")
    ex.add_argument("--out", required=True, help="directory for model.onnx, model.jax_export, deploy.json")
    ex.add_argument("--top-k", type=positive_int, default=None,
                    help="point models: boxes per head kept by the in-graph decode (default 100)")
    ex.add_argument("--max-pillars", type=positive_int, default=None,
                    help=f"point models: pillar slots (default {RUN_PILLARS})")
    ex.add_argument("--input-hw", default=None, metavar="H,W",
                    help="range-Doppler models: the exported input size in map cells (default 256,64: RADDet maps); "
                         "camera models: the letterboxed input in pixels, multiples of 32 (a square takes every image)")
    ex.add_argument("--size", type=positive_int, default=None,
                    help="camera models: export the street frames' letterboxed rectangle at this long side "
                         "(a multiple of 32; default 416: 256 x 416)")
    ex.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE", help="config override")
    qz = sub.add_parser("quantize", help="static INT8 (onnxruntime) of an export, calibrated on synthetic frames")
    qz.add_argument("--onnx", required=True, help="export directory (dsfec export)")
    qz.add_argument("--out", required=True, help="directory for the INT8 model.onnx and deploy.json")
    qz.add_argument("--calib-frames", type=positive_int, default=64,
                    help="synthetic train frames to calibrate on (RD samples; camera: street images)")
    qz.add_argument("--seed", type=int, default=0)
    qz.add_argument("--calibration", default="minmax", choices=("minmax", "percentile", "entropy"),
                    help="how activation ranges are set from the calibration frames")
    b = sub.add_parser("bench", help="batch-1 latency from raw input (points, RD map, image) to boxes per stage, "
                                      "runtime and thread count; --train: training throughput (frames/s, fwd + bwd, "
                                      "GFLOP/s, breakdown)")
    b.add_argument("--models", default=None,
                   help=f"comma-separated zoo names (default {INFER_BENCH_MODELS}); with --train also 'all' "
                        f"(every registered variant), default {TRAIN_BENCH_MODELS}")
    b.add_argument("--runtimes", default="jax,onnx,onnx-int8")
    b.add_argument("--threads", default=None, help="comma-separated thread counts, e.g. 1,2 (default: 1; with --train 2)")
    b.add_argument("--repeats", type=positive_int, default=None, help="timed repetitions (default: 20; with --train 10)")
    b.add_argument("--warmup", type=non_negative_int, default=None, help="untimed repetitions first (default: 3; with --train 2)")
    b.add_argument("--out", default=None, help="write bench.json, bench.md and bench.png here; with --train: the JSON "
                                               "record file (default dsfec_jax/profile/records/train_bench.json)")
    b.add_argument("--json", action="store_true", help="print the records as JSON")
    b.add_argument("--train", action="store_true", help="measure the train step instead (dsfec_jax.profile.training)")
    b.add_argument("--batch", type=positive_int, default=None, help="--train: frames per step (default 8)")
    b.add_argument("--window", type=non_negative_int, default=None,
                   help="--train: training-window cells, 0 = the whole grid (default 96)")
    b.add_argument("--max-pillars", type=positive_int, default=None,
                   help=f"--train: at most this many pillar slots (default {RUN_PILLARS}), sized to the data as training does")
    b.add_argument("--fixed-pillars", action="store_true", help="--train: exactly --max-pillars slots, not sized to the data")
    b.add_argument("--compare", default=None, metavar="FIELD=VALUE[,FIELD=VALUE]",
                   help="--train: also measure each model with these config overrides, interleaved, and report the ratios")
    b.add_argument("--no-breakdown", action="store_true", help="--train: skip the XLA-profiler breakdown of the step")
    b.add_argument("--readme", default=None, help="--train: rewrite the train-bench table in this README")
    b.add_argument("--size", type=positive_int, default=None,
                   help="--train, camera models: the long side training images are letterboxed to "
                        "(a multiple of 32; default 416: 256 x 416 street inputs)")
    for name, split in (("eval", "test"), ("predict", "test")):
        q = sub.add_parser(name, help=f"{name} a zoo model")
        common(q, split)
        q.add_argument("--weights", default=None, help="weights file or training checkpoint (RUN/checkpoints/best, RUN/checkpoints/last/step_N; default: shipped weights)")
        q.add_argument("--score-threshold", type=float, default=None,
                       help=f"keep detections scoring at least this (default: points {POINT_SCORE_THRESHOLD}; "
                            "range-Doppler 0.001, the paper's evaluation setting)")
        q.add_argument("--json", action="store_true")
        q.add_argument("--runtime", default="jax", choices=("jax", "onnx"),
                       help="onnx: run an exported model (--onnx DIR from `dsfec export`) with ONNX Runtime")
        q.add_argument("--onnx", default=None, help="with --runtime onnx: the export directory")
        if name == "predict":
            q.add_argument("--input", nargs="+", action="extend", default=None, metavar="PATH",
                           help="your own files instead of --data: files, folders or globs (sorted, at most 2000 "
                                "files); points: .pcd (nuScenes radar) or .bin (VoD / TJ4DRadSet rows, see "
                                "--columns); range-Doppler: .npy maps (256 x 64 float) or raw TI ADC captures "
                                "(complex .npy); camera: .jpg/.jpeg/.png. --out then holds one entry per file")
            q.add_argument("--columns", default=None,
                           help="with --input .bin point files: their columns, vod | tj4d | nuscenes or names "
                                "x,y,z,... (default: the columns of a model that reads a source's own, RadarNeXt)")
            q.add_argument("--out", required=True,
                           help="detections to write: nuScenes submission JSON (points), COCO results JSON "
                                "(range-Doppler, camera); with --input: {model, inputs: [{file, detections}]}")
            q.add_argument("--png-dir", default=None,
                           help="also write a figure per frame here: BEV in metres (points), the RD map over range "
                                "and velocity (range-Doppler), the image (camera), with a legend and class scores")
            q.add_argument("--png-min-score", type=float, default=None,
                           help="predicted boxes drawn on the figures score at least this (default 0.25, "
                                "ultralytics' predict default; the 3 best when none reaches it)")
            q.add_argument("--gt-out", default=None, help="also write the frames' ground truth in the same format")
    add_edge_commands(sub)
    args = p.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    return args


def model_config(name: str):
    """The registered config of --model (before --set), or exit listing the registered names."""
    from . import zoo

    if name not in zoo.REGISTRY:
        sys.exit(f"--model {name!r}: not a zoo model; available: {', '.join(zoo.available())}")
    return zoo.REGISTRY[name]


def resolved(args):
    """(modality, config, overrides) of --model: the modality refuses the flags it does not take,
    then the config is resolved once from --set and the fields the flags or the data decide."""
    from . import zoo
    from .modalities.registry import modality_of

    modality = modality_of(model_config(args.model))
    modality.commands.refuse(args, args.command)
    overrides = modality.commands.config_fields(args, parse_overrides(args.set))
    try:
        return modality, zoo.config(args.model, **overrides), overrides
    except (TypeError, ValueError) as err:
        sys.exit(f"--set: {err}")


def schedule_preset(profile: str, family) -> str:
    """--schedule's preset: a profile of the family (Family.schedules: 'quick' is yolo_quick for the
    range-Doppler family), or a train.schedules preset named directly."""
    from .train.schedules import SCHEDULES

    name = family.schedules.get(profile, profile)
    if name not in SCHEDULES:
        sys.exit(f"--schedule {profile!r}: expected a profile of {sorted(family.schedules)} or a preset of "
                 f"{sorted(SCHEDULES)}")
    return name


def training_schedule(args, family):
    """The schedule of --schedule with --batch-size, --decay-at and --ema (default: the family's) applied."""
    from .train.schedules import get_schedule

    name = schedule_preset(args.schedule, family)
    changes = {"batch_size": args.batch_size} if args.batch_size else {}
    changes["ema"] = family.weight_ema if args.ema is None else args.ema  # ultralytics' EMA for the YOLOs
    if args.decay_at:
        try:
            changes["decay_at"] = tuple(float(f) for f in args.decay_at.split(","))
        except ValueError:
            sys.exit(f"--decay-at {args.decay_at!r}: expected fractions of training, e.g. 0.7,0.9")
        if not all(0 < f < 1 for f in changes["decay_at"]):
            sys.exit(f"--decay-at {args.decay_at!r}: each fraction must lie in (0, 1)")
    sched = get_schedule(name, **changes)
    if args.decay_at and sched.optimizer == "sgd":
        sys.exit(f"--decay-at: schedule {name!r} (ultralytics' SGD recipe) decays linearly per epoch; "
                 f"--decay-at applies to the step-decay schedules (quick, paper, radarnext)")
    return sched


def check_mesh(args, batch_size: int) -> None:
    """--devices and --batch-size against the mesh, before any data is loaded."""
    from .train import parallel

    try:
        parallel.layout().check_batch(batch_size)
    except parallel.ParallelError as err:
        sys.exit(f"dsfec {args.command}: {err}")


def run_train(args) -> int:
    from . import zoo

    modality, cfg, overrides = resolved(args)
    sched = training_schedule(args, zoo.family_of(cfg))
    check_mesh(args, sched.batch_size)
    info = {"command": command_line(args), "tensorboard": not args.no_tensorboard,
            "data": {"source": args.data, "split": args.split}}
    final = modality.commands.train(args, cfg, overrides, sched, info)
    print(json.dumps({"run_dir": str(args.run_dir), "final": final}))
    return 0


def run_eval_or_predict(args) -> int:
    from .cli_report import print_found, print_scores

    modality, cfg, _ = resolved(args)
    items, detections, predictor, extra = modality.commands.eval_or_predict(args, cfg)
    if getattr(args, "input", None):  # a user's files have no ground truth: say what was found
        return print_found(args, modality, items, detections, **extra)
    return print_scores(args, items, detections, predictor, f"{modality.noun}s", **extra)


def ship_source(args) -> tuple[Path, dict]:
    """The checkpoint --checkpoint picks in --run-dir, and the run's run.json."""
    from .core.run_checkpoints import best_step, last_steps, legacy_checkpoints, legacy_message

    run = Path(args.run_dir)
    if not (run / "run.json").is_file():
        sys.exit(f"dsfec ship: {run / 'run.json'} missing; expected a run directory written by `dsfec train`")
    info = json.loads((run / "run.json").read_text())
    if info.get("model", args.model) != args.model:
        sys.exit(f"dsfec ship: {run} trained {info['model']!r}, not --model {args.model!r}")
    last, best = last_steps(run), best_step(run)
    if not last and legacy_checkpoints(run):
        sys.exit(f"dsfec ship: {legacy_message(run)}")
    if args.checkpoint == "last" and not last:
        sys.exit(f"dsfec ship: {run / 'checkpoints' / 'last'} holds no complete checkpoint")
    if args.checkpoint == "best" and best is None:
        sys.exit(f"dsfec ship: {run / 'checkpoints' / 'best'} holds no checkpoint (no validation has run yet); "
                 "try --checkpoint last")
    return (best if args.checkpoint == "best" else last[-1]), info


def measure_benchmark(predictor, family, split: str, frames: int, source: str | None = None) -> dict:
    """What a weights manifest records: the family's protocol on `frames` items of `split` of its
    embedded synthetic benchmark (or of `source`; data seed 0), the keys its protocol keeps."""
    from .core import progress
    from .modalities.registry import modality_named, protocol

    source = source or family.benchmark
    # generating the benchmark and validating on it (the first split also compiles the predictor)
    with progress.stage(f"measuring {family.metric.name} on {frames} {split} frames of {source} for the manifest"):
        data = modality_named(family.modality).load_samples(family, source, split, frames, 0)
        scores, _ = protocol(family.metric.name).validate(predictor, data)
    return {k: scores[k] for k in family.metric.keep} | {
        "frames": frames, "data_seed": 0, "data": source, "protocol": family.metric.name}


def run_ship(args) -> int:
    from . import zoo
    from .core import checkpoint
    from .core.provenance import versions
    from .core.run_checkpoints import read_extra
    from .modalities.registry import modality_of

    modality = modality_of(model_config(args.model))
    source, info = ship_source(args)
    try:  # the config the run trained
        cfg = zoo.config(args.model, **info.get("overrides", {}))
    except (TypeError, ValueError) as err:
        sys.exit(f"dsfec ship: {Path(args.run_dir) / 'run.json'} overrides: {err}")
    predictor, variables = modality.commands.ship_predictor(cfg, source, info)
    family = zoo.family_of(cfg)
    measured = {split: measure_benchmark(predictor, family, split, args.frames) for split in ("val", "test")}
    manifest = {"model": args.model, "source_checkpoint": str(source),
                "step": read_extra(source).get("step"), "training": info,
                "measured": measured, "ship_command": command_line(args),
                "versions": versions()}
    out = Path(args.out_dir) / f"{args.model}.msgpack" if args.out_dir else zoo.shipped_weights(args.model)
    checkpoint.save(out, variables, manifest)
    print(json.dumps({"weights": str(out), "measured": measured}, indent=2))
    return 0


def run_export(args) -> int:
    modality, cfg, _ = resolved(args)
    out = modality.commands.export(args, cfg, command_line(args))
    print(json.dumps({k: str(v) for k, v in out.items()}, indent=2))
    return 0


def exported_modality(export_dir: str):
    """The Modality record of an export directory's model: its deploy.json's "modality" (range-Doppler
    exports write 'rd', camera exports 'image'; point exports predate the field: 'points')."""
    from .modalities.registry import modality_named

    manifest = Path(export_dir) / "deploy.json"
    if not manifest.is_file():
        sys.exit(f"--onnx {export_dir}: no deploy.json; expected a directory written by `dsfec export`")
    try:
        name = json.loads(manifest.read_text()).get("modality", "points")
    except (json.JSONDecodeError, AttributeError):
        sys.exit(f"--onnx {export_dir}: {manifest} is not a deploy.json object written by `dsfec export`")
    try:
        return modality_named(name)
    except KeyError as err:
        sys.exit(f"--onnx {export_dir}: {manifest}: {err.args[0]}")


def run_quantize(args) -> int:
    out = exported_modality(args.onnx).commands.quantize(args)
    print(json.dumps({k: str(v) if isinstance(v, Path) else v for k, v in out.items()}, indent=2))
    return 0


def bench_threads(text: str) -> list[int]:
    try:
        threads = [int(t) for t in text.split(",")]
    except ValueError:
        sys.exit(f"--threads {text!r}: expected comma-separated integers")
    if min(threads) < 1:
        sys.exit(f"--threads {text!r}: thread counts must be positive")
    return threads


TRAIN_BENCH_FLAGS = ("batch", "window", "max_pillars", "fixed_pillars", "compare", "no_breakdown", "readme", "size")


def bench_models(text: str) -> list[str]:
    """--train's models ('all': every registered variant)."""
    from . import zoo

    if text == "all":
        return zoo.available()
    return [m for m in text.split(",") if m]


def run_train_bench(args) -> int:
    from .modalities.registry import modality_of
    from .profile import training

    window = 96 if args.window is None else args.window
    try:
        settings = training.Settings(batch=args.batch or 8, window=window or None, max_pillars=args.max_pillars or RUN_PILLARS,
                                     repeats=args.repeats or 10, warmup=2 if args.warmup is None else args.warmup,
                                     breakdown=not args.no_breakdown, size_pillars=not args.fixed_pillars,
                                     image_size=args.size or training.IMAGE_SIZE)
        compare = training.parse_compare(args.compare) or None
        if args.readme:
            training.check_readme(args.readme)
        records = training.run(bench_models(args.models or TRAIN_BENCH_MODELS), bench_threads(args.threads or "2"),
                               settings, compare, modality_of=modality_of)
    except (ValueError, RuntimeError) as err:  # unknown model or field, more threads than CPUs, a failed worker
        sys.exit(f"dsfec bench --train: {err}")
    content = training.payload(command_line(args), records, settings, compare)
    record = args.out or training.RECORD
    training.write(record, content)
    if args.readme:
        training.update_readme(args.readme, content, record, modality_of=modality_of)
    print(json.dumps(content, indent=2) if args.json
          else training.markdown(content, record=record, modality_of=modality_of))
    return 0


def run_bench(args) -> int:
    from .core import atomic
    from . import zoo
    from .deploy import bench

    if args.train:
        return run_train_bench(args)
    train_only = [f"--{k.replace('_', '-')}" for k in TRAIN_BENCH_FLAGS if getattr(args, k) not in (None, False)]
    if train_only:
        sys.exit(f"dsfec bench: {', '.join(train_only)} need --train")
    models = [m for m in (args.models or INFER_BENCH_MODELS).split(",") if m]
    runtimes = [r for r in args.runtimes.split(",") if r]
    bad = [m for m in models if m not in zoo.available()] + [r for r in runtimes if r not in bench.RUNTIMES]
    if bad:
        sys.exit(f"dsfec bench: unknown {bad}; models {zoo.available()}, runtimes {list(bench.RUNTIMES)}")
    threads = bench_threads(args.threads or "1")
    try:
        records = bench.run(models, runtimes, threads, args.repeats or 20, 3 if args.warmup is None else args.warmup)
    except (ValueError, RuntimeError) as err:  # e.g. more threads than CPUs, or a failed worker
        sys.exit(f"dsfec bench: {err}")
    table = bench.markdown(records)
    if args.out:
        command = command_line(args)
        atomic.write_json(Path(args.out) / "bench.json", {"command": command, "records": records})
        atomic.write_text(Path(args.out) / "bench.md", table + f"\nCommand: `{command}`\n")
        bench.plot(records, Path(args.out) / "bench.png")
    print(json.dumps(records, indent=2) if args.json else table)
    return 0


LIGHT_COMMANDS = ("serve",)  # run no XLA: the map service starts light and gives memory back


def main(argv=None) -> int:
    args = parse(argv)  # --help and argument errors exit here, before anything heavy
    if args.command in LIGHT_COMMANDS:
        return run_command(args)
    from .core import progress
    from .core.host_memory import prepare_xla_process

    # the watchdog speaks for every wait no stage or bar covers (a restart below ends it with the process)
    with progress.watched(f"dsfec {args.command}"):
        prepare_xla_process()  # XLA's settings first: may restart this command (core/host_memory.py)
        start_parallel(args)
        return run_command(args)


def run_command(args) -> int:
    if args.command in EDGE_COMMANDS:
        from . import cli_edge

        return cli_edge.main(args)
    if args.command == "train":
        return run_train(args)
    if args.command == "ship":
        return run_ship(args)
    if args.command == "export":
        return run_export(args)
    if args.command == "quantize":
        return run_quantize(args)
    if args.command == "bench":
        return run_bench(args)
    return run_eval_or_predict(args)


if __name__ == "__main__":
    raise SystemExit(main())

"""python -m dsfec_jax.profile.device_check [--models ...] [--steps 3] [--out PATH]

On the backend present (or --backend), a few training steps and an inference of each model,
compared with the CPU on the same inputs and weights (on a CPU-only host the reference is the same
backend, and the report says so), with training steps/s, inference latency, peak memory and the
kernel path each program took; exits 1 if any model fails. Writes the record atomically to --out.

An entry point: it builds each model's workload from its modality record (the training batches
the train bench makes, modalities/*/train_bench.py; the depth network's stereo pairs and trainer,
modalities/image/fit_depth.py) and passes them to the modality-free check.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from ...core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import shlex
import sys
from pathlib import Path

MODELS = ("dsfec_s", "baseline", "radarnext_fpn", "yolov8n", "yolov8n_adapter", "shuffle_yolov3", "monodepth_tiny")
RECORDS = Path(__file__).resolve().parents[1] / "records"
PRECISIONS = ("default", "high", "highest")


def positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text}")
    return value


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.profile.device_check", description=__doc__.splitlines()[2])
    p.add_argument("--models", default=",".join(MODELS), help="comma-separated zoo names (detectors or the depth network)")
    p.add_argument("--backend", default=None, help="the backend checked (cpu, gpu, tpu); default: JAX's default backend")
    p.add_argument("--batch", type=positive, default=2, help="frames per training step")
    p.add_argument("--steps", type=positive, default=3, help="training steps compared with the reference")
    p.add_argument("--timed-steps", type=positive, default=5, help="training steps timed after the compared ones")
    p.add_argument("--repeats", type=positive, default=5, help="inference calls timed (median)")
    p.add_argument("--window", type=positive, default=32, help="point models: training window, cells")
    p.add_argument("--pillars", type=positive, default=64, help="point models: pillar slots")
    p.add_argument("--image-size", type=positive, default=64, help="camera models: letterbox long side (a multiple of 32)")
    p.add_argument("--rtol", type=float, default=1e-2, help="relative tolerance of losses and outputs")
    p.add_argument("--atol", type=float, default=1e-5, help="absolute tolerance of losses and outputs")
    p.add_argument("--matmul-precision", choices=PRECISIONS, default="default",
                   help="jax_default_matmul_precision of both sides (default: the backend's, as training runs)")
    p.add_argument("--set", action="append", default=[], metavar="MODEL:FIELD=VALUE[,FIELD=VALUE]",
                   help="config fields of one model (Python literals, as `dsfec train --set`); repeatable")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="the record's path (default: dsfec_jax/profile/records/device_check_<backend>.json)")
    return p.parse_args(argv)


def sides(backend: str | None):
    """(the device checked, the reference CPU device); a clear error for a backend not present."""
    import jax

    try:
        device = jax.devices(backend)[0] if backend else jax.devices()[0]
    except RuntimeError as err:
        sys.exit(f"--backend {backend}: not available here ({err})")
    return device, jax.devices("cpu")[0]


def check_models(names: list[str]) -> None:
    from ... import zoo

    known = set(zoo.available()) | set(zoo.available_auxiliary())
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        sys.exit(f"--models: unknown model(s) {unknown}; available: {sorted(known)}")


def model_overrides(items: list[str], names: list[str]) -> dict[str, dict]:
    """--set items -> {model: {field: value}}, refused naming the item where it is malformed or
    names a model not checked."""
    from ..training import parse_compare

    out: dict[str, dict] = {}
    for item in items:
        model, sep, fields = item.partition(":")
        if not sep or model not in names:
            sys.exit(f"--set {item!r}: expected MODEL:FIELD=VALUE[,FIELD=VALUE] with MODEL one of --models {names}")
        try:
            out.setdefault(model, {}).update(parse_compare(fields))
        except ValueError as err:
            sys.exit(f"--set {item!r}: {err}")
    return out


def detector_workload(name: str, args, overrides: dict):
    """The workload of zoo detector `name`: the train bench's batches (its modality's, at the
    check's small sizes) and its family's quick schedule, as `dsfec bench --train` builds them."""
    from ... import zoo
    from ...modalities.registry import modality_of
    from ...train.schedules import get_schedule
    from ..training import STEP_SCHEDULE, Settings
    from .workload import detector_workload as workload

    settings = Settings(batch=args.batch, window=args.window, max_pillars=args.pillars, size_pillars=False,
                        budget_frames=1, distinct_batches=args.steps, image_size=args.image_size, seed=args.seed,
                        breakdown=False)
    modality = modality_of(name)
    fields = {**modality.train_bench_fields(name, settings), **overrides}
    detector, batches, _ = modality.train_bench_batches(name, fields, settings)
    schedule = get_schedule(zoo.family_of(name).schedules[STEP_SCHEDULE], batch_size=args.batch)
    return workload(detector.config, batches, schedule, args.steps + args.timed_steps, args.seed)


def depth_workload(name: str, args, overrides: dict):
    """The workload of depth network `name`: stereo pairs of the street benchmark and its own
    trainer (monodepth's Adam and loss), inference = its disparities."""
    from ... import zoo
    from ...data.camera.street import StreetConfig
    from ...modalities.image.fit_depth import DepthBatchStream, MonodepthTrainer, monodepth_schedule, render_pairs
    from ...models.depth.net import MonodepthNet
    from .workload import Workload, first_state, on_host, trainer_programs

    cfg = zoo.config(name, **overrides)
    left, right = render_pairs(StreetConfig(render_right=True), args.batch * args.steps, cfg, args.seed)
    stream = DepthBatchStream(left, right, args.batch, args.seed)
    batches = on_host([stream.batch(k) for k in range(args.steps)])
    total = args.steps + args.timed_steps
    schedule = monodepth_schedule(args.batch, total)
    trainer, net = MonodepthTrainer(cfg), MonodepthNet(cfg)
    infer = lambda state, inputs: net.apply({"params": state["params"]}, inputs["left"])  # noqa: E731
    return Workload(name, zoo.auxiliary_of(name).name, None, batches, first_state(trainer, schedule, total, args.seed),
                    lambda kernels: trainer_programs(trainer, schedule, total, infer))


def build_workload(name: str, args, overrides: dict):
    """The workload of `name` with config `overrides`; a field its config lacks is refused by name."""
    from ... import zoo

    build = depth_workload if name in zoo.available_auxiliary() else detector_workload
    try:
        return build(name, args, overrides)
    except TypeError as err:
        sys.exit(f"--set {name}:...: {err}")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse(argv)
    names = [n.strip() for n in args.models.split(",") if n.strip()]
    check_models(names)
    overrides = model_overrides(args.set, names)
    import jax

    from ...core import atomic, progress
    from . import report
    from .check import check_model
    from .verdict import Tolerance

    try:
        tolerance = Tolerance(args.rtol, args.atol)
    except ValueError as err:
        sys.exit(f"--rtol/--atol: {err}")
    device, reference = sides(args.backend)
    precision = None if args.matmul_precision == "default" else args.matmul_precision
    records = []
    with jax.default_matmul_precision(precision):
        for name in names:
            with progress.stage(f"device check: {name} on {device.platform} and {reference.platform}"):
                workload = build_workload(name, args, overrides.get(name, {}))
                records.append(check_model(workload, device, reference, args.steps, tolerance,
                                           args.timed_steps, args.repeats))
    command = " ".join(["python -m dsfec_jax.profile.device_check", *map(shlex.quote, argv)])
    record = report.payload(command, args.seed, vars(args), device, reference, records, args.matmul_precision)
    print("\n".join(report.lines(record)))
    out = Path(args.out) if args.out else RECORDS / f"device_check_{device.platform}.json"
    atomic.write_json(out, record)
    print(f"record: {out}")
    return 0 if record["passed"] else 1


if __name__ == "__main__":
    raise SystemExit(main())

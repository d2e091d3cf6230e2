"""The weight average's gain at the same budget, for a training run of the YOLO or camera families.

One run trained with the EMA (train/ema.py) holds, in each checkpoint, both its raw weights and
their average. The average never feeds back into training, so the raw weights are what the same
command with `--no-ema` trains, step for step. Both are scored here by the manifest's protocol
(`dsfec ship`'s measure_benchmark) on the same val and test items of the run's own benchmark, and
the record keeps the figures, the average's decay at that step, and how the run was trained. A
camera run validates after re-estimating the average's BatchNorm statistics (precise BN); both
weight sets get that here, on the same training images.

    python -m experiments.ema_gain --run-dir runs/ship_v2/yolov8n --frames 200 \\
        --record experiments/records/ema/yolov8n.json
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import json
import shlex
import sys
from pathlib import Path

SPLITS = ("val", "test")


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m experiments.ema_gain", description=__doc__.split("\n\n")[0])
    p.add_argument("--run-dir", required=True, help="a range-Doppler run trained with the weight EMA")
    p.add_argument("--checkpoint", choices=("best", "last"), default="last",
                   help="last: the run's final step (the budget); best: the step its validation chose")
    p.add_argument("--frames", type=int, default=200, help="maps of each split to score")
    p.add_argument("--record", default=None, help="write the record (JSON) here")
    return p.parse_args(argv)


def checkpoint_of(run: Path, which: str) -> Path:
    from dsfec_jax.core.run_checkpoints import best_step, last_steps

    found = best_step(run) if which == "best" else (last_steps(run) or [None])[-1]
    if found is None:
        sys.exit(f"experiments.ema_gain: {run / 'checkpoints'} holds no {which} checkpoint")
    return found


def weights(state: dict, collections, recalibrate=None) -> dict[str, dict]:
    """{'raw': the trained weights, 'ema': their average}: each the model's collections, each with
    its BatchNorm statistics re-estimated by `recalibrate` (the run's precise BN) where given."""
    from dsfec_jax.core.averaged_weights import EMA_KEY
    from dsfec_jax.train.ema import evaluated

    if not isinstance(state.get(EMA_KEY), dict):
        sys.exit("experiments.ema_gain: the checkpoint keeps no weight average (trained with --no-ema?)")
    raw = {k: v for k, v in state.items() if k != EMA_KEY}
    recalibrate = recalibrate or (lambda s: s)
    return {name: {**{k: s[k] for k in collections}, **evaluated(recalibrate(s))}
            for name, s in (("raw", raw), ("ema", state))}


def precise_bn_of(run: Path, info: dict, det):
    """The run's own BN re-estimation before each validation (the camera fits' precise BN, on the
    same training images), or None for a run without it."""
    if not info.get("precise_bn_images"):
        return None
    from dsfec_jax.data.camera.sources import load_camera_images
    from dsfec_jax.modalities.image.fit import bn_recalibration

    images = load_camera_images(info["data"]["source"], "train", info["train_images"], seed=info["seed"])
    return bn_recalibration(det, images, info["schedule"]["batch_size"], info["seed"], info["eval_size"],
                            info["precise_bn_images"], info["max_boxes"], info["aspect"])


def scores(run: Path, path: Path, state: dict, info: dict, frames: int) -> dict:
    from dsfec_jax import zoo
    from dsfec_jax.cli import measure_benchmark
    from dsfec_jax.modalities.registry import modality_of

    cfg = zoo.config(info["model"], **info.get("overrides", {}))
    family, det = zoo.family_of(cfg), zoo.Detector(cfg)
    predictor, _ = modality_of(cfg).commands.ship_predictor(cfg, path, info)  # the run's evaluation settings
    out = {}
    # a run that re-estimated BN before validating did so for the average only: both are re-estimated here
    for name, variables in weights(state, det.collections, precise_bn_of(run, info, det)).items():
        predictor.variables = variables
        out[name] = {split: measure_benchmark(predictor, family, split, frames, info["data"]["source"])
                     for split in SPLITS}
    return out


def gains(measured: dict) -> dict:
    """EMA minus raw, per split and figure."""
    raw, ema = measured["raw"], measured["ema"]
    return {split: {k: round(ema[split][k] - v, 4) for k, v in raw[split].items() if isinstance(v, float)}
            for split in SPLITS}


def main(argv=None) -> int:
    import numpy as np

    from dsfec_jax.core import atomic
    from dsfec_jax.core.provenance import versions
    from dsfec_jax.core.run_checkpoints import read_extra, read_state
    from dsfec_jax.train.ema import decay

    args = parse(argv)
    run = Path(args.run_dir)
    info = json.loads((run / "run.json").read_text())
    path = checkpoint_of(run, args.checkpoint)
    state = read_state(path)  # read once: the updates count and both weight sets
    updates = int(state["ema"]["updates"])
    measured = scores(run, path, state, info, args.frames)
    record = {"command": "python -m experiments.ema_gain " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:])),
              "seed": info.get("seed"), "versions": versions(), "training": info,
              "checkpoint": {"path": str(path), "step": read_extra(path).get("step"), "ema_updates": updates,
                             "decay": round(float(np.asarray(decay(updates))), 4)},
              "measured": measured, "ema_minus_raw": gains(measured)}
    if args.record:
        atomic.write_json(args.record, record)
    print(json.dumps({k: record[k] for k in ("checkpoint", "ema_minus_raw")}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())

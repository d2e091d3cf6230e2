"""Shipping the depth network's weights with the detectors' manifest rules (`dsfec depth ship`).

    ship_depth_weights("runs/depth/monodepth_street_cont", zoo.shipped_weights("monodepth_street"),
                       "dsfec depth ship --run-dir runs/depth/monodepth_street_cont")

The shipped manifest holds what a detector's does (`dsfec ship`): "model", "source_checkpoint",
"step", "training" (the run's run.json: command, seed, config, schedule, data, versions; plus the
runs it continued: "init_chain", each start's weights, step, sha256, command and seed, read from
the run directory that made them or from the shipped file's own manifest), "measured" (the
shipped file's dense depth metrics on the street benchmark's test frames: `dsfec depth eval`'s
figures), "ship_command" and "versions".

`convert_depth_weights` rewrites a file of the network's first format (before it joined the zoo:
its provenance at the manifest's top level) in that layout, its params unchanged, and measures it;
the shipped file was converted so (its manifest's "convert_command").
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ... import zoo
from ...core import checkpoint
from ...core.run_checkpoints import run_dir_of
from ...core.provenance import versions
from ...data.camera.street import StreetConfig, StreetDataset
from .depth import WEIGHTS_NAME, MonodepthPredictor, load_depth_variables, save_depth_weights
from .fit_depth import evaluate_dense

MEASURED_FRAMES = 50  # test frames a shipped file is measured on (`dsfec depth eval`'s default)
MAX_CHAIN = 16        # runs followed back through "init" (a loop of hand-edited run.json files ends)


def measure_depth(config, variables: dict, frames: int = MEASURED_FRAMES, seed: int = 0,
                  street_config: StreetConfig | None = None) -> dict:
    """{'test': dense metrics of these weights on `frames` test frames (data seed `seed`), with
    the frames and seed}: what `dsfec depth eval --frames N --seed S` prints."""
    data = StreetDataset(street_config or StreetConfig(), "test", seed, frames)
    return {"test": {**evaluate_dense(MonodepthPredictor(config, variables), data), "frames": frames, "data_seed": seed}}


def ship_depth_weights(run_dir: str | os.PathLike, out: str | os.PathLike, ship_command: str,
                       frames: int = MEASURED_FRAMES, street_config: StreetConfig | None = None) -> dict:
    """A finished run's weights to OUT with their provenance and measured figures -> OUT's manifest
    (module docstring)."""
    run_dir = Path(run_dir)
    weights = run_dir / WEIGHTS_NAME
    if not weights.is_file():
        raise ValueError(f"{weights}: not found; expected the weights of a finished `dsfec depth train` run")
    config, variables = load_depth_variables(weights)
    run = _run_json(run_dir)
    training = {**run, "train_frames": (run.get("data") or {}).get("frames"), "init_chain": _init_chain(run)}
    save_depth_weights(out, config, variables, training, source_checkpoint=str(weights),
                       step=checkpoint.read_manifest(weights).get("step"),
                       measured=measure_depth(config, variables, frames, street_config=street_config),
                       ship_command=ship_command, versions=versions())
    return checkpoint.read_manifest(Path(out))


def convert_depth_weights(weights: str | os.PathLike, out: str | os.PathLike, convert_command: str,
                          frames: int = MEASURED_FRAMES, street_config: StreetConfig | None = None) -> dict:
    """A weights file of the network's first format to OUT in the zoo's layout, measured -> OUT's
    manifest. Its params are written unchanged; its provenance moves under "training"."""
    old = checkpoint.read_manifest(weights)
    if "training" in old or not old.get("format"):
        raise ValueError(f"{checkpoint.manifest_path(weights)}: already in the zoo's layout (or no depth weights "
                         "manifest); nothing to convert")
    config, variables = load_depth_variables(weights)
    save_depth_weights(out, config, variables, zoo.training_record(weights), source_checkpoint=old.get("source"),
                       step=old.get("step"), measured=measure_depth(config, variables, frames, street_config=street_config),
                       ship_command=old.get("ship_command"), convert_command=convert_command, versions=versions())
    return checkpoint.read_manifest(Path(out))


def _run_json(run_dir: Path) -> dict:
    path = run_dir / "run.json"
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: not readable ({err}); expected the run.json of a depth training run") from err


def _init_chain(run: dict) -> list[dict]:
    """The weights a run started from, and theirs, back to a run from scratch. Where the start
    was a shipped file rather than a run directory, its own training record says how it was trained."""
    chain = []
    while run.get("init") and len(chain) < MAX_CHAIN:
        init = dict(run["init"])
        path = Path(init["path"])
        parent = run_dir_of(path) if "checkpoints" in path.parts else path.parent
        if (parent / "run.json").is_file():
            run = _run_json(parent)
            chain.append({**init, "command": run.get("command"), "seed": run.get("seed")})
            continue
        shipped = zoo.training_record(init["path"])
        chain.append({**init, "command": shipped.get("command"), "seed": shipped.get("seed"),
                      **({"init_chain": shipped["init_chain"]} if shipped.get("init_chain") else {})})
        break
    return chain

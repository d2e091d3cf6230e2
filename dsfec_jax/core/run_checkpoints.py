"""A training run's checkpoints, written by Orbax's CheckpointManager.

RUN_DIR/checkpoints/
  last/step_0000300/{state, extra, _CHECKPOINT_METADATA}   the last `keep` training states
  best/step_0000200/...                                    the state with the best validation score

Two managers, because one manager keeps either the newest N or (with `best_fn`) the N best, and a
run needs both: resuming wants the newest state, shipping wants the best-scoring one, and a best
state may be far older than the last `keep`. `extra` is a JSON item beside the state: the step, the
loss, and for the best one the score and its evaluation (what the msgpack manifests held).

Orbax writes each step into a temporary directory and renames it when complete, so a kill at any
instant leaves either a finished step or a temporary directory, which the managers never list and
remove when they next open. Saves are asynchronous: `save` returns once Orbax has copied the
arrays to the host, so the train step may donate the state's buffers right after; the writing
goes on in the background and the next save, a read, or `close` waits for it. Every process of a
multi-host run must make the same calls: Orbax writes the arrays collectively and the JSON from
the primary process.

Run directories from before Orbax (checkpoints/step_*.msgpack with .json manifests, best.msgpack)
are converted on their first resume (`convert_legacy`); their files move to
checkpoints/msgpack_before_orbax/. Shipped weights stay msgpack (core/checkpoint.py).
"""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path

import jax
import numpy as np
import orbax.checkpoint as ocp

from . import checkpoint

log = logging.getLogger(__name__)

LAST, BEST = "last", "best"
STEP_PREFIX, STEP_DIGITS = "step", 7  # step_0000300: the names the msgpack checkpoints had
LEGACY_DIR = "msgpack_before_orbax"


def checkpoints_dir(run_dir: str | os.PathLike) -> Path:
    return Path(run_dir).absolute() / "checkpoints"  # Orbax refuses relative paths (--run-dir runs/x)


def _options(**kwargs) -> ocp.CheckpointManagerOptions:
    return ocp.CheckpointManagerOptions(step_prefix=STEP_PREFIX, step_format_fixed_length=STEP_DIGITS, **kwargs)


class RunCheckpoints:
    """The last-N and best managers of one run directory; what the training loop calls."""

    def __init__(self, run_dir: str | os.PathLike, keep: int = 3, best_key: str = "car_mAP"):
        self.run_dir, self.best_key = Path(run_dir).absolute(), best_key
        base = checkpoints_dir(run_dir)
        # cleanup_tmp_directories: a kill mid-save left a temporary step; remove it so it is neither
        # mistaken for a checkpoint nor left to fill the disk
        self.last = ocp.CheckpointManager(base / LAST, options=_options(max_to_keep=keep, cleanup_tmp_directories=True))
        self.best = ocp.CheckpointManager(base / BEST, options=_options(
            max_to_keep=1, best_fn=lambda metrics: metrics[best_key], best_mode="max", cleanup_tmp_directories=True))

    def restore(self, state: dict) -> dict:
        """The newest complete checkpoint's state, shaped and placed as `state` (the fresh one,
        returned when there is none); a run directory of msgpack checkpoints is converted first."""
        if self.last.latest_step() is None:
            convert_legacy(self, state)
        step = self.last.latest_step()
        if step is None:
            return state
        abstract = jax.tree.map(ocp.utils.to_shape_dtype_struct, state)
        try:
            return self.last.restore(step, args=ocp.args.Composite(state=ocp.args.StandardRestore(abstract)))["state"]
        except (ValueError, KeyError) as err:  # Orbax names the mismatched leaf
            raise ValueError(f"{step_path(self.last, step)}: does not fit the model being trained ({err})") from err

    def save(self, step: int, state: dict, extra: dict) -> None:
        """Start writing `state` as step `step` of the last N (returns once the arrays are on the host)."""
        _save(self.last, step, state, {"step": step, **extra})

    def save_best(self, step: int, state: dict, score: float, extra: dict) -> None:
        """Start writing `state` as the best so far, with its score under best_key."""
        _save(self.best, step, state, {"step": step, self.best_key: score, **extra}, {self.best_key: score})

    def best_score(self) -> float:
        """The recorded best score; -inf when no best checkpoint was completed."""
        step = self.best.latest_step()
        return -np.inf if step is None else read_extra(step_path(self.best, step)).get(self.best_key, -np.inf)

    def latest(self) -> Path | None:
        """The newest complete last-N checkpoint, once pending writes are done."""
        self.last.wait_until_finished()
        step = self.last.latest_step()
        return None if step is None else step_path(self.last, step)

    def close(self) -> None:
        """Wait for the pending writes and release the managers."""
        self.last.close()
        self.best.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _save(manager: ocp.CheckpointManager, step: int, state: dict, extra: dict, metrics: dict | None = None) -> None:
    if step in manager.all_steps():  # a resume that re-reaches a step saved before it was killed
        manager.wait_until_finished()
        manager.delete(step)
    manager.save(step, args=ocp.args.Composite(state=ocp.args.StandardSave(state), extra=ocp.args.JsonSave(extra)),
                 metrics=metrics, force=True)


def step_path(manager: ocp.CheckpointManager, step: int) -> Path:
    return Path(manager.directory) / f"{STEP_PREFIX}_{step:0{STEP_DIGITS}d}"


def _finished_steps(directory: Path) -> list[Path]:
    """The complete step directories under one manager's directory, oldest first."""
    if not directory.is_dir():
        return []
    found = [p for p in directory.glob(f"{STEP_PREFIX}_*") if p.is_dir() and is_checkpoint(p)]
    return sorted(found, key=lambda p: p.name)


def last_steps(run_dir: str | os.PathLike) -> list[Path]:
    """A run's complete last-N checkpoints, oldest first (read only: nothing is waited for or removed)."""
    return _finished_steps(checkpoints_dir(run_dir) / LAST)


def best_step(run_dir: str | os.PathLike) -> Path | None:
    found = _finished_steps(checkpoints_dir(run_dir) / BEST)
    return found[-1] if found else None


def is_checkpoint(path: str | os.PathLike) -> bool:
    """A complete Orbax step directory of a run (a temporary one, killed mid-write, is not)."""
    path = Path(path)
    return ((path / "state").is_dir() and not ocp.utils.is_tmp_checkpoint(path)
            and ocp.utils.is_checkpoint_finalized(path))


def resolve(path: str | os.PathLike) -> Path:
    """PATH as a step directory: a step itself, or a manager's directory (checkpoints/best,
    checkpoints/last) for its newest step; PATH unchanged otherwise."""
    path = Path(path).absolute()
    if path.is_dir() and not is_checkpoint(path):
        found = _finished_steps(path)
        if found:
            return found[-1]
    return path


def readable(path: str | os.PathLike) -> bool:
    """A weights file or a training checkpoint that can be read (what --weights accepts)."""
    return Path(path).is_file() or is_checkpoint(resolve(path))


def read_state(path: str | os.PathLike) -> dict:
    """A checkpoint's whole state as host numpy arrays, without knowing the model (a predictor's
    weights, a scoring worker's supernet): containers come back as dicts and lists."""
    path = resolve(path)
    if not is_checkpoint(path):
        raise FileNotFoundError(f"{path}: not a complete training checkpoint (expected RUN/checkpoints/last/step_N "
                                "or RUN/checkpoints/best)")
    item = path / "state"
    metadata = ocp.StandardCheckpointer().metadata(item).item_metadata
    as_numpy = jax.tree.map(lambda _: ocp.RestoreArgs(restore_type=np.ndarray), metadata)
    return ocp.PyTreeCheckpointer().restore(item, args=ocp.args.PyTreeRestore(restore_args=as_numpy))


def read_extra(path: str | os.PathLike) -> dict:
    """A checkpoint's JSON item: its step, loss, and for a best checkpoint the score and evaluation."""
    path = resolve(path)
    return ocp.Checkpointer(ocp.JsonCheckpointHandler()).restore(path / "extra")


def run_dir_of(path: str | os.PathLike) -> Path:
    """The run directory a checkpoint sits in: above RUN/checkpoints/{last,best}/step_N, and above
    RUN/checkpoints/NAME.msgpack for the msgpack ones."""
    path = Path(path)
    for parent in path.parents:
        if parent.name == "checkpoints":
            return parent.parent
    return path.parent.parent


def legacy_checkpoints(run_dir: str | os.PathLike) -> list[Path]:
    """The msgpack checkpoints a run directory holds from before Orbax, oldest first."""
    return sorted(checkpoints_dir(run_dir).glob("step_*.msgpack"))


def legacy_message(run_dir: str | os.PathLike) -> str:
    """What a reader says of a run directory that holds only msgpack checkpoints."""
    return (f"{checkpoints_dir(run_dir)} holds msgpack checkpoints written before Orbax (step_*.msgpack); "
            "resume the run once (the same `dsfec train` command, which converts them and goes on), or pass "
            "one of those files to --weights")


def convert_legacy(run: RunCheckpoints, state: dict) -> None:
    """Write the newest complete msgpack checkpoint of a pre-Orbax run (and its best.msgpack) as
    Orbax checkpoints, in the structure of `state`, then move the msgpack files aside. An incomplete
    one (killed while saving) is skipped for the one before, as the msgpack loop did."""
    base = checkpoints_dir(run.run_dir)
    found = legacy_checkpoints(run.run_dir)
    newest = next((p for p in reversed(found) if checkpoint.problem(p) is None), None)
    if newest is None:
        return
    log.warning("%s: converting the msgpack checkpoint %s (and best.msgpack) to Orbax checkpoints; the msgpack "
                "files move to %s", base, newest.name, base / LEGACY_DIR)
    manifest = checkpoint.read_manifest(newest)
    run.save(int(manifest.get("step", 0)), checkpoint.load(newest, state), _without_checksum(manifest))
    best = base / "best.msgpack"
    if best.is_file() and checkpoint.problem(best) is None:
        manifest = _without_checksum(checkpoint.read_manifest(best))
        score = manifest.pop(run.best_key, None)
        if score is not None:
            run.save_best(int(manifest.pop("step", 0)), checkpoint.load(best, state), score, manifest)
    run.last.wait_until_finished()
    run.best.wait_until_finished()
    if jax.process_index() == 0:  # one mover; the files are the same for every process
        (base / LEGACY_DIR).mkdir(exist_ok=True)
        for path in [*found, best]:
            for p in (path, checkpoint.manifest_path(path)):
                if p.exists():
                    shutil.move(p, base / LEGACY_DIR / p.name)


def _without_checksum(manifest: dict) -> dict:
    return {k: v for k, v in manifest.items() if k not in checkpoint.CHECKSUM_KEYS}

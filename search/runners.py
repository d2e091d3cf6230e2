"""Run a list of trials: locally one after another, or as Ray Tune trials. Both skip trials the
journal already holds and append each result as it finishes, so a killed sweep loses at most
the trial in flight."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Callable

from .journal import Journal
from .ray_session import ray_session
from .report import headline
from .trial import run_trial


def summary(record: dict) -> str:
    """'<headline> 12.34, GFLOPs 5.67' of an ok record, for the progress log."""
    key, title = headline([record])
    return f"{title} {record['metrics'][key]:.2f}, GFLOPs {record['costs']['gflops']:.2f}"


def pending(trials: list[dict], journal: Journal, retry_failed: bool = False) -> list[dict]:
    done = journal.done(retry_failed)
    return [t for t in trials if t["key"] not in done]


def run_local(trials: list[dict], run_dir: str | Path, retry_failed: bool = False,
              log: Callable[[str], None] = print, progress: bool = True) -> list[dict]:
    """Run the pending trials here, one after another; `progress`: each trial's training bar and
    stage lines (compiling, profiling) on stderr."""
    journal = Journal(run_dir)
    todo = pending(trials, journal, retry_failed)
    log(f"{len(trials) - len(todo)} of {len(trials)} trials already in {journal.path}; running {len(todo)}")
    for i, trial in enumerate(todo, 1):
        log(f"[{i}/{len(todo)}] {trial['label']} (seed {trial['seed']})")
        record = run_trial(trial, run_dir, progress)
        journal.append(record)
        log(f"    {record['status']}: " + (summary(record) if record["status"] == "ok" else record["error"]))
    return journal.records()


def run_ray(trials: list[dict], run_dir: str | Path, address: str | None = None, retry_failed: bool = False,
            cpus_per_trial: float = 1.0, log: Callable[[str], None] = print) -> list[dict]:
    """Run the pending trials as Ray Tune trials (a local Ray started here, or the cluster at
    `address`); each finished trial's record is appended to the journal as it arrives."""
    import json
    import os

    try:
        import ray
        from ray import tune
    except ImportError as err:
        raise SystemExit("--backend ray needs Ray Tune: pip install 'dsfec_jax[ray]'") from err

    run_dir = Path(run_dir).resolve()
    journal = Journal(run_dir)
    todo = pending(trials, journal, retry_failed)
    log(f"{len(trials) - len(todo)} of {len(trials)} trials already in {journal.path}; running {len(todo)} on Ray")
    if not todo:
        return journal.records()

    class JournalCallback(tune.Callback):
        def on_trial_result(self, iteration, trials, trial, result, **info):
            if "record_json" in result:
                record = json.loads(result["record_json"])
                journal.append(record)
                log(f"    {record['label']} (seed {record['seed']}): {record['status']}")

    # the Ray this process already runs, or one started here (search/ray_session.py)
    with contextlib.nullcontext() if ray.is_initialized() else ray_session(address, os.cpu_count()):
        trainable = tune.with_resources(_ray_trainable, {"cpu": cpus_per_trial})
        tuner = tune.Tuner(trainable,
                           param_space={"trial": tune.grid_search(todo), "run_dir": str(run_dir)},
                           run_config=tune.RunConfig(name="search", storage_path=str(run_dir / "ray"),
                                                     callbacks=[JournalCallback()], verbose=0))
        tuner.fit()
    return journal.records()


def _ray_trainable(config: dict) -> dict:
    import json

    return {"record_json": json.dumps(run_trial(config["trial"], config["run_dir"]))}

"""Run a list of trials: locally one after another, or as Ray Tune trials. Both skip trials the
journal already holds and append each result as it finishes, so a killed sweep loses at most
the trial in flight."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from .journal import Journal
from .trial import run_trial


def pending(trials: list[dict], journal: Journal) -> list[dict]:
    done = journal.done()
    return [t for t in trials if t["key"] not in done]


def run_local(trials: list[dict], run_dir: str | Path, log: Callable[[str], None] = print) -> list[dict]:
    journal = Journal(run_dir)
    todo = pending(trials, journal)
    log(f"{len(trials) - len(todo)} of {len(trials)} trials already in {journal.path}; running {len(todo)}")
    for i, trial in enumerate(todo, 1):
        log(f"[{i}/{len(todo)}] {trial['label']} (seed {trial['seed']})")
        record = run_trial(trial, run_dir)
        journal.append(record)
        log(f"    {record['status']}: " + (f"car mAP {record['metrics']['car_mAP']:.2f}, GFLOPs "
                                             f"{record['costs']['gflops']:.2f}" if record["status"] == "ok"
                                             else record["error"]))
    return journal.records()

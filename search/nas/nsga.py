"""A second strategy over the same space and scores: Optuna's NSGA-II, multi-objective.

Objectives: maximise the metric, minimise one cost (params, GFLOPs or latency); each limit is a
trial constraint (`Trial.set_constraint`, Optuna 5's successor of `constraints_func`: a value > 0
is infeasible), so the Pareto front (`study.best_trials`)
holds feasible subnets only. Each generation is asked as one batch (Optuna's ask-and-tell), its
feasible subnets are scored in one call of the same score function the evolution uses (so a
Ray-backed scorer parallelises both), and an infeasible subnet is never scored: it is told the
placeholder score 0 and its constraint marks it infeasible. Subnets the journal already holds
(NSGA-II may propose one twice, or a resumed run again) are not rescored.

Resume: the study lives in `RUN_DIR/optuna.journal` (Optuna's JournalStorage), so a killed search
picks up its finished trials and asks only for the rest; trials left running by the kill are marked
failed. Optuna does not store the sampler's random state, so a resumed NSGA-II run proposes
different (equally valid) later subnets than an uninterrupted one would: the evolution
(evolution.py) is the strategy whose resumed run is exact.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from .evolution import Costs, Scores, score_missing
from .space import SearchSpace, key
from ..journal import Journal

PLACEHOLDER_SCORE = 0.0  # told for an infeasible subnet, which its constraint keeps off the front


def _optuna():
    try:
        import optuna
    except ImportError as err:  # an optional dependency: pip install -e ".[nas]"
        raise ImportError("the NSGA-II strategy needs Optuna: pip install -e '.[nas]' (optuna==5.0.*)") from err
    return optuna


def run_nsga2(space: SearchSpace, scores: Scores, costs: Costs, run_dir: str | Path, cost: str = "params",
              limits: dict | None = None, population: int = 50, generations: int = 20, metric: str = "mAP50",
              seed: int = 0, log: Callable[[str], None] = print):
    """Run (or resume) the study; returns it. `cost` is the second objective's key in `costs()`."""
    optuna = _optuna()
    limits = dict(limits or {})
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(run_dir / "optuna.journal")))
    sampler = optuna.samplers.NSGAIISampler(population_size=population, seed=seed)
    study = optuna.create_study(study_name=f"nas-{space.name}", storage=storage, sampler=sampler,
                                directions=["maximize", "minimize"], load_if_exists=True)
    _fail_interrupted(study, optuna)
    journal = Journal(run_dir)
    total = population * generations
    while (finished := _finished(study, optuna)) < total:
        batch, generation = min(population, total - finished), finished // population
        trials = [study.ask() for _ in range(batch)]
        genes = [tuple(t.suggest_categorical(c.name, list(range(len(c.options)))) for c in space.choices) for t in trials]
        spent = [costs(g) for g in genes]
        violation = [[float(s[name] - limit) for name, limit in limits.items()] for s in spent]
        feasible_genes = [g for g, v in zip(genes, violation) if all(x <= 0 for x in v)]
        results = score_missing(space, scores, costs, journal, feasible_genes, metric, generation)
        for trial, g, s, v in zip(trials, genes, spent, violation):
            feasible = all(x <= 0 for x in v)
            for name, value in zip(limits, v):
                trial.set_constraint(name, value)
            trial.set_user_attr("key", key(g))
            trial.set_user_attr("costs", s)
            score = float(results[key(g)][metric]) if feasible else PLACEHOLDER_SCORE
            study.tell(trial, [score, float(s[cost])])
        log(f"NSGA-II: {_finished(study, optuna)} of {total} trials, {sum(all(x <= 0 for x in v) for v in violation)} "
            f"of {batch} feasible, Pareto front {len(study.best_trials)}")
    return study


def _finished(study, optuna) -> int:
    return sum(t.state == optuna.trial.TrialState.COMPLETE for t in study.trials)


def _fail_interrupted(study, optuna) -> None:
    """Trials a killed run left RUNNING would never finish: mark them failed (not counted)."""
    for t in study.trials:
        if t.state == optuna.trial.TrialState.RUNNING:
            study._storage.set_trial_state_values(t._trial_id, optuna.trial.TrialState.FAIL)


def pareto_front(study) -> list[dict]:
    """The feasible non-dominated trials: {key, score, cost, costs}, best score first."""
    front = [{"key": t.user_attrs["key"], "score": t.values[0], "cost": t.values[1], "costs": t.user_attrs["costs"]}
             for t in study.best_trials]
    return sorted(front, key=lambda r: (-r["score"], r["cost"], r["key"]))

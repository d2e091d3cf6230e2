"""One NAS run, end to end: SPOS supernet -> constrained search -> reports (resumable throughout).

RUN_DIR/supernet holds the supernet's training run (train.loop: resumes from its last
checkpoint), RUN_DIR/journal.jsonl every scored subnet, RUN_DIR/evolution.json (or
optuna.journal) the search's progress, and RUN_DIR/report.md + pareto_*.png the reports. A killed
run started again with the same command picks up where it stopped. The space's engine
(engines.py) trains its supernet and scores its subnets.
"""

from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path
from typing import Callable

from dsfec_jax import zoo
from dsfec_jax.core import atomic
from dsfec_jax.core.environment import environment

from ..journal import Journal
from .engines import PROFILES, engine_for
from .evolution import Evolution, EvolutionSettings, progress_table
from .latency import RECORDS, LatencyTable
from .register import register
from .report import write_report
from .space import SearchSpace, key
from .spaces import get_space
from .spos import model_costs, subnet_costs
from .standalone import choose, ranking_study, retrain
from .standalone import markdown as ranking_markdown


class CachedCosts:
    """subnet_costs (+ the latency table's prediction, `latency_ms`, given a table), each subnet's
    computed once (the evolution asks again when it journals)."""

    def __init__(self, space: SearchSpace, latency: LatencyTable | None = None):
        self.space, self.latency, self.cache = space, latency, {}

    def __call__(self, genes) -> dict:
        genes = tuple(genes)
        if genes not in self.cache:
            costs = subnet_costs(self.space, genes)
            if self.latency is not None:
                costs["latency_ms"] = self.latency.predict(genes)
            self.cache[genes] = costs
        return self.cache[genes]


def latency_table(space: SearchSpace, path: str | Path | None, needed: bool) -> LatencyTable | None:
    """The space's latency table (search/nas/records/latency_SPACE.json unless `path`), or None
    when there is none and no limit needs it."""
    path = Path(path) if path else RECORDS / f"latency_{space.name}.json"
    if not path.exists():
        if needed:
            raise FileNotFoundError(f"--max-latency-ms needs a latency table: {path} does not exist; build it with "
                                    f"python -m search.nas.latency --space {space.name} --threads 1")
        return None
    return LatencyTable.load(path, space)


def shipped_reference(model: str) -> dict | None:
    """A hand-designed zoo model's point: its shipped weights' stand-alone val mAP and its costs."""
    manifest = Path(str(zoo.shipped_weights(model)) + ".json")
    if not manifest.exists():
        return None
    val = json.loads(manifest.read_text())["measured"]["val"]
    costs = model_costs(model, {})
    return {"label": f"{model} (stand-alone, shipped)", **costs, **{k: val.get(k) for k in ("mAP50", "mAP50_95")}}


def run_nas(space_name: str, run_dir: str | Path, profile: str = "quick", strategy: str = "evolution",
            limits: dict | None = None, seed: int = 0, objective: str = "params", command: str = "",
            progress: bool = True, register_as: str | None = None, latency_path: str | None = None,
            standalone: int = 0, spread: int = 0, spread_by: str = "score", backend: str = "local",
            address: str | None = None, workers: int | None = None, sampling: str = "uniform",
            record_path: str | Path | None = None, log: Callable[[str], None] = print) -> Path:
    """Supernet, search, reports; with `standalone` / `spread`, the top subnets (and `spread` more
    across the ranking) trained stand-alone and the ranking study (search.nas.standalone); `register_as`
    then registers the best stand-alone subnet instead of the best inherited one, and `record_path`
    receives the study with the run's command, seed and environment (a record to ship: RUN_DIR is
    scratch). `backend` "ray":
    the search's subnets are scored by `workers` Ray actors (search.nas.ray_scoring; the local Ray
    started here or the cluster at `address`) and the stand-alone trainings run as Ray Tune trials."""
    if strategy not in ("evolution", "nsga2"):
        raise ValueError(f"--strategy {strategy!r}; expected 'evolution' or 'nsga2'")
    space = get_space(space_name)
    p, run_dir, limits = PROFILES[profile], Path(run_dir), dict(limits or {})
    table = latency_table(space, latency_path, "latency_ms" in limits)  # before anything trains
    t0 = time.perf_counter()
    # the supernet trains here, in the driver; `sampling`: SPOS's rule (spos.SAMPLINGS), kept in its run.json
    engine = engine_for(space)(space, p, profile, run_dir, seed, progress,
                               **({"sampling": sampling} if sampling != "uniform" else {}))
    steps, metric = engine.steps, engine.metric
    log(f"supernet: {steps} SPOS steps ({time.perf_counter() - t0:.0f} s including any earlier part of this run)")
    costs = CachedCosts(space, table)
    with contextlib.ExitStack() as stack:
        scorer = engine.scorer
        if backend == "ray":
            from .ray_scoring import RayScorer, nas_factory

            scorer = stack.enter_context(RayScorer(nas_factory(space.name, p, profile, run_dir, seed), workers, address,
                                                   max_workers=p.population, log=log))
        if strategy == "evolution":
            settings = EvolutionSettings(p.population, p.generations, p.top_k, metric=metric, seed=seed)
            progress_text = progress_table(Evolution(space, scorer, costs, run_dir, settings, limits, log, progress).run())
        else:
            from .nsga import pareto_front, run_nsga2

            study = run_nsga2(space, scorer, costs, run_dir, objective, limits, p.population, p.generations, metric,
                              seed, log)
            progress_text = f"NSGA-II, {len(study.trials)} trials; Pareto front ({metric} vs {objective}): " + ", ".join(
                f"{r['key']} ({r['score']:.2f}, {r['cost']:.4g})" for r in pareto_front(study))
    oneshot_s = _oneshot_seconds(run_dir, time.perf_counter() - t0)
    hand = space.base_genes()  # one subnet, scored here (a resumed finished search then starts no Ray)
    references = [{"label": f"{space.base} (inherited)", **costs(hand), **engine.scorer([hand])[0]}]
    records = [r for r in Journal(run_dir).records() if r.get("status") == "ok"]
    references += [r for r in (shipped_reference(m) for m in engine.shipped) if r]  # scored on the same val data
    meta = {"command": command, "space": space.name, "space_size": space.size(), "profile": profile,
            "strategy": strategy, "limits": limits, "seed": seed, "supernet_steps": steps, "sampling": sampling,
            "wall_s": round(time.perf_counter() - t0, 1), "environment": environment()}
    header = (f"# One-shot NAS: {space.name} ({space.description}; {space.size():,} subnets)\n\n"
              f"Profile `{profile}` on the {engine.data}: {steps} SPOS steps, {len(records)} subnets scored with "
              f"inherited weights (BN recalibrated on {engine.calibration}); limits {limits or 'none'}. "
              f"Inherited-weight {metric} ranks subnets; it is not a stand-alone score.")
    study = None
    if standalone or spread:
        chosen = choose(records, metric, standalone, spread, spread_by)
        log(f"stand-alone: training {len(chosen)} subnets ({standalone} top, {len(chosen) - min(standalone, len(chosen))} "
            f"across the ranking, and {space.base}'s own architecture as the reference) in {run_dir / 'standalone'}")
        # the hand-designed architecture trained the same way: the reference the searched ones face
        extra = [] if any(r["key"] == key(hand) for r in chosen) else [{"key": key(hand)}]
        trained = retrain(space, chosen + extra, run_dir, profile, seed, backend, address, command, log, engine.init,
                          progress)
        references += standalone_reference(space.base, hand, trained, costs, metric)
        study = ranking_study(chosen, trained, metric, oneshot_s, len(records))
        atomic.write_json(run_dir / "ranking.json", study)
        meta["wall_s"] = round(time.perf_counter() - t0, 1)
        if record_path is not None:
            atomic.write_json(record_path, {**meta, "ranking": study})
            log(f"ranking study record: {record_path}")
    report = write_report(run_dir, header, progress_text, records, metric, references, meta,
                          ranking_markdown(study) if study else None)
    if register_as:
        _register_best(space, records, study, metric, register_as, meta, report, log)
    return report


def standalone_reference(base: str, hand, trained: list[dict], costs, metric: str) -> list[dict]:
    """The hand-designed architecture's stand-alone point among `trained` ([] if it failed)."""
    done = [r for r in trained if r["label"] == key(hand) and r.get("status") == "ok"]
    return [{"label": f"{base} (stand-alone, this recipe)", **costs(hand), metric: done[0]["metrics"][metric]}] if done else []


def _oneshot_seconds(run_dir: Path, this_process_s: float) -> float:
    """The one-shot part's wall time (supernet + search), kept in RUN_DIR/timing.json, so the
    stand-alone cost ratio compares against the whole one-shot cost (accumulated_seconds)."""
    return accumulated_seconds(run_dir / "timing.json", "oneshot_s", this_process_s)


def accumulated_seconds(path: Path, field: str, this_process_s: float) -> float:
    """A resumable job's wall time kept in `path`: the process that finishes the job adds its time
    to what earlier ones recorded, later ones (which find it finished) add nothing; a process killed
    before the end records nothing, which makes the figure a lower bound."""
    timing = json.loads(path.read_text()) if path.exists() else {field: 0.0, "complete": False}
    if not timing.get("complete"):
        timing = {**timing, field: round(timing[field] + this_process_s, 1), "complete": True}
        atomic.write_json(path, timing)
    return float(timing[field])


def _register_best(space: SearchSpace, records: list[dict], study: dict | None, metric: str, name: str, meta: dict,
                   report: Path, log: Callable[[str], None]) -> None:
    """Register the best stand-alone subnet when the run retrained some, else the best inherited one."""
    inherited = {r["key"]: r for r in records}
    if study and study["best_standalone"]:
        best = inherited[study["best_standalone"]]
        alone = next(p["standalone"] for p in study["pairs"] if p["key"] == best["key"])
        scores, how = {"inherited": {metric: best[metric]}, "standalone": {metric: alone}}, f"{alone:.2f} stand-alone"
    else:
        best = min(records, key=lambda r: (-r[metric], r["key"]))
        scores, how = {"inherited": {metric: best[metric]}}, f"{best[metric]:.2f} inherited"
    register(space, tuple(best["genes"]), name,
             {**{k: meta[k] for k in ("command", "profile", "strategy", "limits", "seed", "supernet_steps")},
              **scores, "costs": best["costs"], "report": str(report), "versions": meta["environment"].get("versions")})
    log(f"registered {name}: subnet {best['key']} ({metric} {how}, {best['costs']['params'] / 1e6:.3f} M params)")

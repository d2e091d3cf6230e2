"""The constrained evolutionary search of the YOLOv8n-Adapter paper (Sec. 3.4), resumable.

Generation 0 draws `population` random subnets; every later generation makes `mutants` mutants
and `crossovers` crossovers of the current top k and fills the rest of the population with random
subnets (megvii's SinglePathOneShot); the top k of everything scored so far go on. A subnet
already proposed is never proposed again, and one that breaks a constraint (params, GFLOPs,
latency: cheap to compute) is rejected before it is scored. Each operator gives up after 10x its
quota of attempts (megvii's rule), so a tight constraint cannot loop forever.

Everything a run decides is a pure function of the seed, the settings and the scores: generation
g draws from `default_rng([seed, g])`, the visited set is what earlier generations proposed, and
ties in score go to the lower key. Scores are kept in the run directory's journal (one record per
scored subnet, search.journal) and each finished generation in `evolution.json` (atomic writes),
so a killed search resumes where it stopped, rescoring nothing, and ends with the population an
uninterrupted run ends with (a test).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from dsfec_jax.core import atomic
from dsfec_jax.core.progress import stage

from ..journal import Journal
from .space import Genes, SearchSpace, from_key, key

ATTEMPTS_PER_SLOT = 10  # megvii: mutation / crossover stop after 10x their target count of attempts


@dataclasses.dataclass(frozen=True)
class EvolutionSettings:
    """The paper's P = 50, T = 20, top k = 15; mutation probability 0.1 (the paper gives none)."""

    population: int = 50
    generations: int = 20
    top_k: int = 15
    mutation_prob: float = 0.1
    mutants: int | None = None  # default population // 2
    crossovers: int | None = None  # default population // 2
    metric: str = "mAP50"  # the score to maximise, a key of the score function's records
    seed: int = 0

    def __post_init__(self):
        for field in ("population", "generations", "top_k"):
            if getattr(self, field) < 1:
                raise ValueError(f"EvolutionSettings.{field} must be >= 1, got {getattr(self, field)}")
        if not 0.0 <= self.mutation_prob <= 1.0:
            raise ValueError(f"EvolutionSettings.mutation_prob must lie in [0, 1], got {self.mutation_prob}")

    @property
    def quotas(self) -> tuple[int, int]:
        """(mutants, crossovers) per generation after the first."""
        half = self.population // 2
        return (half if self.mutants is None else self.mutants, half if self.crossovers is None else self.crossovers)


Costs = Callable[[Genes], dict]  # a subnet's cheap costs: params, gflops, latency_ms, ...
Scores = Callable[[list[Genes]], list[dict]]  # records with the metric, for a batch of subnets


def feasible(costs: dict, limits: dict) -> bool:
    """Every limited cost at or under its limit (a cost the limits name must be present)."""
    for name, limit in limits.items():
        if name not in costs:
            raise KeyError(f"constraint on {name!r}, but the cost function gives only {sorted(costs)}")
    return all(costs[name] <= limit for name, limit in limits.items())


class Evolution:
    """One search in `run_dir`: `run()` scores what is missing and returns the final state."""

    def __init__(self, space: SearchSpace, scores: Scores, costs: Costs, run_dir: str | Path,
                 settings: EvolutionSettings = EvolutionSettings(), limits: dict | None = None,
                 log: Callable[[str], None] = print, progress: bool = False):
        self.space, self.scores, self.costs, self.settings = space, scores, costs, settings
        self.progress = progress  # a stage line while a generation's subnets are drawn and sized
        self.limits = dict(limits or {})
        self.run_dir = Path(run_dir)
        self.journal = Journal(self.run_dir)
        self.state_path = self.run_dir / "evolution.json"
        self.log = log

    # -- state ---------------------------------------------------------------------------------
    def header(self) -> dict:
        return {"space": self.space.name, "base": self.space.base, "choices": list(self.space.names),
                "settings": dataclasses.asdict(self.settings), "limits": self.limits}

    def load_state(self) -> dict:
        if not self.state_path.exists():
            return {**self.header(), "generations": []}
        state = json.loads(self.state_path.read_text())
        for field, value in self.header().items():
            if state.get(field) != json.loads(json.dumps(value)):
                raise ValueError(f"{self.state_path}: this run directory holds a search with {field} = "
                                 f"{state.get(field)!r}, not {value!r}; use another run directory")
        return state

    def scored(self) -> dict[str, dict]:
        return {r["key"]: r for r in self.journal.records() if r.get("status") == "ok"}

    # -- the search ----------------------------------------------------------------------------
    def run(self) -> dict:
        state = self.load_state()
        done = len(state["generations"])
        visited = {k for gen in state["generations"] for k in gen["proposed"] + gen["rejected"]}
        top = list(state["generations"][-1]["top"]) if done else []
        for g in range(done, self.settings.generations):
            rng = np.random.default_rng([self.settings.seed, g])
            # sizing a new subnet traces its network (seconds each): a generation's draw can take a minute
            with stage(f"generation {g}: drawing {self.settings.population} subnets and tracing their sizes",
                       enabled=self.progress):
                proposed, rejected = self.propose(g, rng, top, visited)
            records = self.score_missing(proposed, g)
            top = self.top_k(top + [key(p) for p in proposed], records)
            visited.update(key(p) for p in proposed)
            visited.update(rejected)
            state["generations"].append(self.summary(g, proposed, rejected, top, records))
            atomic.write_text(self.state_path, json.dumps(state, indent=1))
            self.log(progress_line(state["generations"][-1], self.settings.metric))
        return state

    def propose(self, g: int, rng: np.random.Generator, top: list[str], visited: set[str]):
        """(new subnets to score, keys of the rejected ones): generation g's candidates."""
        taken, rejected = set(visited), []
        out: list[Genes] = []

        def fill(draw: Callable[[], Genes], quota: int) -> None:
            want = len(out) + quota
            for _ in range(ATTEMPTS_PER_SLOT * quota):
                if len(out) >= want:
                    return
                genes = draw()
                k = key(genes)
                if k in taken:
                    continue
                taken.add(k)
                if feasible(self.costs(genes), self.limits):
                    out.append(genes)
                else:
                    rejected.append(k)

        parents = [from_key(k) for k in top]
        if g > 0 and parents:
            mutants, crossovers = self.settings.quotas
            fill(lambda: self.space.mutate(parents[rng.integers(len(parents))], rng, self.settings.mutation_prob), mutants)
            fill(lambda: self.space.crossover(parents[rng.integers(len(parents))], parents[rng.integers(len(parents))], rng),
                 crossovers)
        fill(lambda: self.space.sample(rng), self.settings.population - len(out))
        return out, rejected

    def score_missing(self, proposed: list[Genes], g: int) -> dict[str, dict]:
        return score_missing(self.space, self.scores, self.costs, self.journal, proposed, self.settings.metric, g)

    def top_k(self, keys: Sequence[str], records: dict[str, dict]) -> list[str]:
        """The best k distinct keys by the metric, ties to the lower key."""
        metric = self.settings.metric
        ranked = sorted(set(keys), key=lambda k: (-float(records[k][metric]), k))
        return ranked[:self.settings.top_k]

    def summary(self, g, proposed, rejected, top, records) -> dict:
        metric = self.settings.metric
        top_scores = [float(records[k][metric]) for k in top]
        return {"generation": g, "proposed": [key(p) for p in proposed], "rejected": rejected,
                "top": top, "top_scores": top_scores,
                "best": top_scores[0] if top_scores else None,
                "mean_top": float(np.mean(top_scores)) if top_scores else None}


def score_missing(space: SearchSpace, scores: Scores, costs: Costs, journal: Journal, genes: list[Genes],
                  metric: str, generation: int) -> dict[str, dict]:
    """{key: record} of every scored subnet, after scoring those of `genes` the journal lacks in
    one batch (the score function may spread it over workers) and journalling them one by one: a
    kill loses at most the batch in flight. Both strategies score through here."""
    have = {r["key"]: r for r in journal.records() if r.get("status") == "ok"}
    todo = list({key(g): g for g in genes if key(g) not in have}.values())
    for g, result in zip(todo, scores(todo) if todo else []):
        if metric not in result:
            raise KeyError(f"the score function gave no {metric!r} for subnet {key(g)} (it gave {sorted(result)})")
        record = {"key": key(g), "genes": list(g), "choices": space.decode(g), "generation": generation,
                  "status": "ok", "costs": costs(g), **result}
        journal.append(json.loads(json.dumps(record, default=float)))
        have[record["key"]] = record
    return have


def progress_line(gen: dict, metric: str) -> str:
    best = "-" if gen["best"] is None else f"{gen['best']:.2f}"
    mean = "-" if gen["mean_top"] is None else f"{gen['mean_top']:.2f}"
    return (f"generation {gen['generation']:2d}: {len(gen['proposed'])} scored, {len(gen['rejected'])} rejected, "
            f"best {metric} {best}, mean of top {len(gen['top'])} {mean}")


def progress_table(state: dict) -> str:
    """Generation by generation: how many were scored and rejected, the best and the top-k mean."""
    metric = state["settings"]["metric"]
    lines = [f"| generation | scored | rejected by constraints | best {metric} | mean {metric} of top k | best subnet |",
             "|---|---|---|---|---|---|"]
    for gen in state["generations"]:
        best = "-" if gen["best"] is None else f"{gen['best']:.2f}"
        mean = "-" if gen["mean_top"] is None else f"{gen['mean_top']:.2f}"
        lines.append(f"| {gen['generation']} | {len(gen['proposed'])} | {len(gen['rejected'])} | {best} | {mean} | "
                     f"{gen['top'][0] if gen['top'] else '-'} |")
    return "\n".join(lines)

"""Stand-alone retraining of searched subnets, and how well their inherited scores ranked them.

The one-shot search ranks subnets by mAP with inherited supernet weights. This step trains chosen
subnets from scratch as ordinary zoo configs (the space's overrides of its base model) through the
project's sweep machinery: search trials with the family's recipe, a journal in RUN_DIR/standalone
(resumable), the local or Ray backend, and the sweep report with its paired-bootstrap intervals.
Chosen are the top `top` subnets by inherited score plus `spread` more spaced evenly over the rest
of the inherited ranking, so the ranking study sees good and bad subnets, not only a top cluster
whose scores lie within noise of each other. The study is Kendall's tau between inherited and
stand-alone mAP over every retrained subnet with its exact permutation p-value (search.ranking),
the question SPOS-style searches live or die by (Yu et al. 2020, "Evaluating the search phase of
NAS": weight-sharing rankings often correlate weakly with stand-alone ones).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from dsfec_jax.core import atomic

from ..journal import Journal
from ..ranking import kendall_tau, tau_p_value
from ..recipes import get_recipe
from ..report import write_reports
from ..runners import run_local, run_ray
from ..trial import make_trial
from .space import SearchSpace, from_key

SUBDIR = "standalone"


def choose(records: list[dict], metric: str, top: int, spread: int, spread_by: str = "score") -> list[dict]:
    """The top `top` records by inherited `metric` (ties by key), then `spread` more evenly spaced
    over the rest: by inherited rank (`spread_by` "score": the best and worst of the rest included
    when spread >= 2) or over a cost's range ("params", "gflops", "latency_ms": the subnets nearest
    to evenly spaced values from the rest's smallest to its largest cost, so the study spans the
    constraint's range)."""
    ranked = sorted((r for r in records if r.get("status") == "ok"), key=lambda r: (-r[metric], r["key"]))
    chosen, rest = ranked[:top], ranked[top:]
    if not spread or not rest:
        return chosen
    if spread_by == "score":
        at = np.unique(np.round(np.linspace(0, len(rest) - 1, min(spread, len(rest)))).astype(int))
        return chosen + [rest[i] for i in at]
    if any(spread_by not in r["costs"] for r in rest):
        raise ValueError(f"--spread-by {spread_by!r}: not a cost every scored subnet has "
                         f"(they have {sorted(rest[0]['costs'])})")
    costs = np.array([r["costs"][spread_by] for r in rest], float)
    picked: list[int] = []
    for target in np.linspace(costs.min(), costs.max(), min(spread, len(rest))):
        free = [i for i in range(len(rest)) if i not in picked]
        picked.append(min(free, key=lambda i: (abs(costs[i] - target), rest[i]["key"])))
    return chosen + [rest[i] for i in picked]


def retrain(space: SearchSpace, chosen: list[dict], run_dir: Path, recipe: str, seed: int = 0,
            backend: str = "local", address: str | None = None, command: str = "",
            log: Callable[[str], None] = print, init: str | None = None, progress: bool = True) -> list[dict]:
    """Train every chosen subnet stand-alone (one search trial each, the family's `recipe`) -> the
    journal's records of the chosen ones. `init`: the weights every subnet starts from
    (search.inherit.describe; the supernet's own start), else the recipe's choice. `progress`: each
    local trial's bar and stage lines on stderr."""
    out = run_dir / SUBDIR
    data = get_recipe(recipe, space.base).data
    trials = [make_trial(space.base, {"label": r["key"], "overrides": space.overrides(from_key(r["key"]))},
                         recipe, data, seed, init=init) for r in chosen]
    atomic.write_json(out / "search.json", {
        "title": f"{space.name}: searched subnets trained stand-alone", "base": space.base, "base_label": None,
        "profile": recipe, "data": data, "seeds": 1, "strategy": "train", "command": command,
        "candidates": [t["label"] for t in trials]})
    if backend == "ray":
        run_ray(trials, out, address)
    else:
        run_local(trials, out, log=log, progress=progress)
    write_reports(out)
    keys = {t["key"] for t in trials}
    return [r for r in Journal(out).records() if r["key"] in keys]


def ranking_study(chosen: list[dict], standalone: list[dict], metric: str, oneshot_s: float | None = None,
                  scored: int | None = None) -> dict:
    """Inherited vs stand-alone `metric` of every retrained subnet: pairs, Kendall tau, exact p;
    with the one-shot run's wall time `oneshot_s` (supernet + search) and its `scored` subnet
    count, the cost ratio: seconds per subnet stand-alone against one-shot."""
    by_label = {r["label"]: r for r in standalone if r.get("status") == "ok"}
    pairs = [{"key": r["key"], "inherited": r[metric], "standalone": by_label[r["key"]]["metrics"][metric],
              "params": by_label[r["key"]]["costs"]["params"]} for r in chosen if r["key"] in by_label]
    inherited = [p["inherited"] for p in pairs]
    alone = [p["standalone"] for p in pairs]
    tau = kendall_tau(inherited, alone) if len(pairs) > 1 else float("nan")
    p_value = tau_p_value(inherited, alone) if len(pairs) > 1 else None
    best = max(pairs, key=lambda p: (p["standalone"], p["key"]), default=None)
    walls = [by_label[p["key"]]["wall_s"] for p in pairs if "wall_s" in by_label[p["key"]]]
    cost = {"standalone_s_per_subnet": round(float(np.mean(walls)), 1) if walls else None,
            "oneshot_s_per_subnet": round(oneshot_s / scored, 1) if oneshot_s and scored else None}
    if cost["standalone_s_per_subnet"] and cost["oneshot_s_per_subnet"]:
        cost["ratio"] = round(cost["standalone_s_per_subnet"] / cost["oneshot_s_per_subnet"], 1)
    return {"metric": metric, "cost": cost, "n": len(pairs), "tau": None if np.isnan(tau) else round(tau, 4),
            "p_value": None if p_value is None else round(p_value, 4), "pairs": pairs,
            "best_standalone": best["key"] if best else None,
            "best_inherited": pairs[0]["key"] if pairs else None}


def markdown(study: dict) -> str:
    """The report section: the pairs table and the verdict."""
    lines = [f"| subnet | params (M) | inherited {study['metric']} | stand-alone {study['metric']} |",
             "|---|---|---|---|"]
    for p in study["pairs"]:
        lines.append(f"| {p['key']} | {p['params'] / 1e6:.3f} | {p['inherited']:.2f} | {p['standalone']:.2f} |")
    if study["n"] < 2:
        verdict = f"{study['n']} subnet(s) retrained: too few for a ranking correlation."
    elif study["tau"] is None:
        verdict = (f"{study['n']} subnets retrained; Kendall tau is undefined: one of the two rankings is all ties "
                   f"(e.g. every stand-alone {study['metric']} 0 on a tiny budget).")
    else:
        p = "not computed past 8 subnets" if study["p_value"] is None else f"exact one-sided p = {study['p_value']:.3f}"
        verdict = (f"Kendall tau between inherited and stand-alone {study['metric']} over {study['n']} subnets: "
                   f"{study['tau']:+.2f} ({p}). Best stand-alone: {study['best_standalone']}; best inherited: "
                   f"{study['best_inherited']}.")
    cost = study.get("cost", {})
    if cost.get("ratio"):
        verdict += (f" Cost: {cost['standalone_s_per_subnet']:.0f} s per subnet stand-alone against "
                    f"{cost['oneshot_s_per_subnet']:.0f} s one-shot (supernet and search over the scored subnets): "
                    f"{cost['ratio']:.0f}x.")
    return "\n".join(lines) + "\n\n" + verdict

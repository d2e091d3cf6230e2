"""How steady a search's ranking is across seeds: split-half agreement of the candidates' ranks.

With S seeds per candidate, split the seeds into two disjoint groups of k (every such split, for
k = 1 .. S // 2), rank the candidates by their mean over each group, and compare the two rankings:
Kendall's tau-b between them, and whether they name the same top candidate. The mean tau at k is
how well a table of k seeds reproduces itself, the split-half reliability of a k-seed table;
how it grows with k says whether more seeds pay. The bootstrap of search.significance answers a
different question (how uncertain each difference is); this one needs no model of the noise.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from .ranking import kendall_tau

MAX_SPLITS = 2000  # splits per k past which a fixed-seed sample of them is used


def seed_scores(records: list[dict], key: str) -> tuple[list[str], list[int], np.ndarray]:
    """(labels, seeds, (candidates, seeds) values of `key`) over the seeds every candidate finished."""
    by_label: dict[str, dict[int, float]] = {}
    for r in records:
        value = r.get("metrics", {}).get(key) if r.get("status") == "ok" else None
        by_label.setdefault(r["label"], {})
        if value is not None:
            by_label[r["label"]][int(r.get("seed", 0))] = float(value)
    seeds = sorted(set.intersection(*(set(v) for v in by_label.values()))) if by_label else []
    labels = list(by_label)
    values = np.array([[by_label[label][s] for s in seeds] for label in labels])
    return labels, seeds, values.reshape(len(labels), len(seeds))  # (n, 0), not (n,), with no shared seed


def splits(n_seeds: int, k: int, rng_seed: int = 0) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
    """Unordered pairs of disjoint k-subsets of range(n_seeds) (a fixed-seed sample past MAX_SPLITS)."""
    out = [(a, b) for a in itertools.combinations(range(n_seeds), k)
           for b in itertools.combinations([s for s in range(n_seeds) if s not in a], k) if a < b]
    if len(out) > MAX_SPLITS:
        picks = np.random.default_rng(rng_seed).choice(len(out), MAX_SPLITS, replace=False)
        out = [out[i] for i in sorted(picks)]
    return out


def split_half(values: np.ndarray, k: int) -> dict:
    """Agreement of k-seed means over every split of the seeds (columns of `values`) into two halves."""
    taus, same_top = [], []
    for a, b in splits(values.shape[1], k):
        mean_a, mean_b = values[:, list(a)].mean(1), values[:, list(b)].mean(1)
        taus.append(kendall_tau(list(mean_a), list(mean_b)))
        same_top.append(int(np.argmax(mean_a)) == int(np.argmax(mean_b)))
    taus = [t for t in taus if not math.isnan(t)]
    return {"k": k, "splits": len(same_top), "tau_mean": float(np.mean(taus)) if taus else None,
            "tau_min": min(taus, default=None), "tau_max": max(taus, default=None),
            "same_top": float(np.mean(same_top))}


def agreement(records: list[dict], key: str) -> dict | None:
    """Split-half agreement for k = 1 .. S // 2 over the seeds all candidates share; None with
    fewer than 2 such seeds or 3 candidates (no ranking to compare)."""
    labels, seeds, values = seed_scores(records, key)
    if len(seeds) < 2 or len(labels) < 3:
        return None
    return {"metric": key, "candidates": len(labels), "seeds": seeds,
            "by_k": [split_half(values, k) for k in range(1, len(seeds) // 2 + 1)]}


def summary(result: dict, title: str) -> str:
    """One line per k for report.md."""
    parts = [f"{r['k']} vs {r['k']} seed{'s' if r['k'] > 1 else ''}: tau {r['tau_mean']:.2f} "
             f"({r['tau_min']:.2f} to {r['tau_max']:.2f} over {r['splits']} splits), same top candidate in "
             f"{100 * r['same_top']:.0f} %" for r in result["by_k"] if r["tau_mean"] is not None]
    n = len(result["seeds"])
    return (f"Seed agreement ({title}; seeds {', '.join(map(str, result['seeds']))} split into two disjoint "
            f"groups, candidates ranked by each group's mean, Kendall tau between the two rankings): "
            + "; ".join(parts) + f". (How well this {n}-seed table itself would reproduce takes {2 * n} seeds "
            "to measure: `--seeds` more on the same RUN_DIR resumes it.)")

"""How sure a search table is of its ranking: a paired bootstrap over the validation frames.

Every candidate of a sweep is scored on the same validation frames, and each trial record keeps its
Car match table (`dsfec_jax.metrics.resampling`): which predictions hit at each threshold, per frame.
Drawing the frames with replacement and re-scoring every candidate on the same draw gives the spread
that a finite evaluation set alone puts into the table; pairing (each draw scores every candidate)
removes the frames' shared difficulty from the differences against the base row. With several seeds
the draw also picks seeds with replacement (the same seed indices for every candidate, since a
one-shot seed is one supernet shared by all of them) and a candidate's value is the mean over the
drawn seeds, so training noise widens the intervals too; with one seed it cannot, and the summary
says so.
"""

from __future__ import annotations

import numpy as np

from dsfec_jax.metrics.resampling import MatchTable, bootstrap_counts, resampled_ap

from .ranking import kendall_tau

CLASS = "car"          # the class of the DSFEC tables' headline (Car mAP over 0.5/1/2/4 m)
RESAMPLES = 1000


def matches_entry(tables: dict[str, MatchTable]) -> dict:
    """The record's "matches" field: {class: base64 match table} (evaluate.score's "match_tables")."""
    return {name: table.to_text() for name, table in tables.items()}


def candidate_tables(records: list[dict]) -> dict[str, list[MatchTable]] | None:
    """label -> match tables of its finished seeds; None if any finished trial has none (a journal
    from before match tables were recorded, or a protocol without them, such as VoD's 3D AP)."""
    out: dict[str, list[MatchTable]] = {}
    for r in records:
        if r["status"] != "ok":
            continue
        text = r.get("matches", {}).get(CLASS)
        if text is None:
            return None
        out.setdefault(r["label"], []).append(MatchTable.from_text(text, f"trial {r['key']} ({r['label']})"))
    return out or None


def _car_map(tables: list[MatchTable], counts) -> float:
    return 100.0 * float(np.mean([resampled_ap(t, counts).mean() for t in tables]))


def _draws(groups: dict[str, list[MatchTable]], frames: int, resamples: int, seed: int) -> np.ndarray:
    """(B, C) Car mAP of every candidate on each draw of frames (and seeds, if there are several)."""
    counts = bootstrap_counts(frames, resamples, seed)
    n_seeds = max(len(t) for t in groups.values())
    picks = np.random.default_rng([seed, 1]).random((resamples, n_seeds))  # shared: seed draws stay paired
    out = np.empty((resamples, len(groups)))
    for c, tables in enumerate(groups.values()):
        per_seed = np.array([[100.0 * resampled_ap(t, k).mean() for t in tables] for k in counts])  # (B, S)
        chosen = (picks * len(tables)).astype(int) if len(tables) > 1 else np.zeros((resamples, 1), int)
        out[:, c] = np.take_along_axis(per_seed, chosen, axis=1).mean(1)
    return out


def paired_bootstrap(records: list[dict], base_label: str | None, resamples: int = RESAMPLES,
                     seed: int = 0) -> dict | None:
    """Bootstrap summary of the Car-mAP column, or None when the records carry no match tables."""
    groups = candidate_tables(records)
    if groups is None:
        return None
    labels = list(groups)
    samples = groups[labels[0]][0].samples
    for label, tables in groups.items():
        if any(t.samples != samples for t in tables):
            raise ValueError(f"candidate {label!r} was scored on other validation frames than {labels[0]!r}; "
                             "a paired bootstrap needs the same frames for every candidate")
    point = np.array([_car_map(groups[label], None) for label in labels])
    boot = _draws(groups, len(samples), resamples, seed)  # (B, C)
    taus = np.array([kendall_tau(list(b), list(point)) for b in boot]) if len(labels) > 1 else np.ones(1)
    taus = taus[~np.isnan(taus)]  # tau is undefined where every candidate ties (e.g. all at 0 mAP)
    out = {"class": CLASS, "frames": len(samples), "seeds": max(len(t) for t in groups.values()),
           "resamples": resamples, "seed": seed,
           "point": dict(zip(labels, point.round(4).tolist())),
           "sd": dict(zip(labels, boot.std(0, ddof=1).round(4).tolist())),
           "best": labels[int(point.argmax())],
           "p_best_stays_best": round(float(np.mean(boot.argmax(1) == point.argmax())), 4),
           "rank_tau_mean": round(float(taus.mean()), 4) if len(taus) else None,
           "rank_tau_p05": round(float(np.percentile(taus, 5)), 4) if len(taus) else None}
    if base_label in groups:
        diff = boot - boot[:, [labels.index(base_label)]]
        out["base"] = base_label
        out["delta"] = {label: {"point": round(float(point[i] - point[labels.index(base_label)]), 4),
                                "ci95": np.percentile(diff[:, i], [2.5, 97.5]).round(4).tolist(),
                                "p_better": round(float(np.mean(diff[:, i] > 0)), 4)}
                        for i, label in enumerate(labels) if label != base_label}
    return out


def summary(result: dict) -> str:
    """The paragraph under a report's table."""
    sds = list(result["sd"].values())
    seeds = result.get("seeds", 1)
    over = f"the {result['frames']} validation frames" + (f" and the {seeds} seeds" if seeds > 1 else "")
    line = (f"{'Evaluation and training' if seeds > 1 else 'Evaluation'} noise (paired bootstrap over {over}, "
            f"{result['resamples']} resamples, seed {result['seed']}): Car mAP sd "
            f"{min(sds):.2f}-{max(sds):.2f} per candidate; Kendall tau between a resample's ranking and the "
            + (f"table's: mean {result['rank_tau_mean']:.2f} (5th percentile {result['rank_tau_p05']:.2f})"
               if result["rank_tau_mean"] is not None else "table's: undefined (every candidate ties)")
            + f"; the top candidate ({result['best']}) stays top in "
              f"{100 * result['p_best_stays_best']:.0f} % of resamples.")
    if "delta" in result:
        sure = [label for label, d in result["delta"].items() if d["ci95"][0] > 0 or d["ci95"][1] < 0]
        line += (f" Differences from the base whose 95 % interval excludes 0: "
                 f"{', '.join(sure) if sure else 'none'}.")
    if seeds > 1:
        return line + f" With {seeds} seeds the training-noise part of these intervals is itself rough."
    return line + " Training noise (seeds) is not in these intervals; `--seeds N` adds it."

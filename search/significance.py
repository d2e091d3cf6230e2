"""How sure a search table is of its ranking: a paired bootstrap over the validation frames.

Every candidate of a sweep is scored on the same validation frames, and each trial record keeps the
match tables of its protocol's classes (`dsfec_jax.metrics.resampling`): which predictions hit at
each threshold, per frame (DSFEC: Car at the four centre distances; the RD tables: every class at
COCO's IoU thresholds). Drawing the frames with replacement and re-scoring every candidate on the
same draw gives the spread that a finite evaluation set alone puts into the table; pairing (each
draw scores every candidate) removes the frames' shared difficulty from the differences against the
base row. The resampled figure is the protocol's `Statistic`: the mean over its classes (those with
ground truth in the draw) of each class's AP averaged over its thresholds, so Car mAP for DSFEC and
mAP@50 for the RD tables, the tables' own headline. With several seeds the draw also picks seeds
with replacement (the same seed indices for every candidate, since a one-shot seed is one supernet
shared by all of them) and a candidate's value is the mean over the drawn seeds, so training noise
widens the intervals too; with one seed it cannot, and the summary says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from dsfec_jax.metrics.resampling import MatchTable, bootstrap_counts, table_ap

from .ranking import kendall_tau

RESAMPLES = 1000


@dataclasses.dataclass(frozen=True)
class Statistic:
    """The resampled figure: `name` as reports write it; `classes` (None: every class a record
    keeps); `thresholds` averaged (None: every one the tables hold)."""

    name: str = "Car mAP"
    classes: tuple[str, ...] | None = ("car",)
    thresholds: tuple[float, ...] | None = None

    @classmethod
    def of(cls, metric) -> "Statistic":
        """From a family's MetricProtocol (match_class "*": every class)."""
        every = metric.match_class in (None, "*")
        return cls(metric.interval_statistic, None if every else (metric.match_class,), metric.interval_thresholds)

    def columns(self, table: MatchTable) -> list[int]:
        if self.thresholds is None:
            return list(range(len(table.thresholds)))
        out = [i for i, t in enumerate(table.thresholds) if any(abs(t - want) < 1e-9 for want in self.thresholds)]
        if len(out) != len(self.thresholds):
            raise ValueError(f"{self.name}: thresholds {list(self.thresholds)} are not all in the {table.class_name!r} "
                             f"match table (it holds {list(table.thresholds)})")
        return out

    def value(self, tables: dict[str, MatchTable], counts) -> float:
        """The statistic (percent) of one seed's tables on one draw of frames (counts None: each once)."""
        per_class = []
        for table in tables.values():
            cols = self.columns(table)
            ap = table_ap(table, counts, cols)[cols]
            if not np.isnan(ap).all():  # COCO: a class without ground truth in the draw is not averaged
                per_class.append(float(np.mean(ap)))
        return 100.0 * float(np.mean(per_class)) if per_class else 0.0


def matches_entry(tables: dict[str, MatchTable]) -> dict:
    """The record's "matches" field: {class: base64 match table} (evaluate.score's "match_tables")."""
    return {name: table.to_text() for name, table in tables.items()}


def candidate_tables(records: list[dict], statistic: Statistic = Statistic()
                     ) -> dict[str, list[dict[str, MatchTable]]] | None:
    """label -> one {class: match table} per finished seed; None if any finished trial lacks a
    class the statistic needs (a journal from before match tables were recorded, or a protocol
    without them, such as VoD's 3D AP)."""
    out: dict[str, list[dict[str, MatchTable]]] = {}
    for r in records:
        if r["status"] != "ok":
            continue
        kept = r.get("matches") or {}
        names = statistic.classes if statistic.classes is not None else tuple(kept)
        if not names or any(n not in kept for n in names):
            return None
        out.setdefault(r["label"], []).append(
            {n: MatchTable.from_text(kept[n], f"trial {r['key']} ({r['label']}), class {n}") for n in names})
    return out or None


def _draws(groups: dict[str, list[dict[str, MatchTable]]], frames: int, resamples: int, seed: int,
           statistic: Statistic) -> np.ndarray:
    """(B, C) statistic of every candidate on each draw of frames (and seeds, if there are several)."""
    counts = bootstrap_counts(frames, resamples, seed)
    n_seeds = max(len(t) for t in groups.values())
    picks = np.random.default_rng([seed, 1]).random((resamples, n_seeds))  # shared: seed draws stay paired
    out = np.empty((resamples, len(groups)))
    for c, seeds in enumerate(groups.values()):
        per_seed = np.array([[statistic.value(tables, k) for tables in seeds] for k in counts])  # (B, S)
        chosen = (picks * len(seeds)).astype(int) if len(seeds) > 1 else np.zeros((resamples, 1), int)
        out[:, c] = np.take_along_axis(per_seed, chosen, axis=1).mean(1)
    return out


def paired_bootstrap(records: list[dict], base_label: str | None, resamples: int = RESAMPLES,
                     seed: int = 0, statistic: Statistic = Statistic()) -> dict | None:
    """Bootstrap summary of the statistic's column (Car mAP by default), or None when the records
    carry no match tables for it."""
    groups = candidate_tables(records, statistic)
    if groups is None:
        return None
    labels = list(groups)
    samples = next(iter(groups[labels[0]][0].values())).samples
    for label, seeds in groups.items():
        if any(t.samples != samples for tables in seeds for t in tables.values()):
            raise ValueError(f"candidate {label!r} was scored on other validation frames than {labels[0]!r}; "
                             "a paired bootstrap needs the same frames for every candidate")
    point = np.array([np.mean([statistic.value(tables, None) for tables in groups[label]]) for label in labels])
    boot = _draws(groups, len(samples), resamples, seed, statistic)  # (B, C)
    taus = np.array([kendall_tau(list(b), list(point)) for b in boot]) if len(labels) > 1 else np.ones(1)
    taus = taus[~np.isnan(taus)]  # tau is undefined where every candidate ties (e.g. all at 0 mAP)
    out = {"statistic": statistic.name, "frames": len(samples), "seeds": max(len(t) for t in groups.values()),
           "resamples": resamples, "seed": seed,
           "point": dict(zip(labels, point.round(4).tolist())),
           "sd": dict(zip(labels, boot.std(0, ddof=1).round(4).tolist())),
           # each candidate's own 95 % interval (the plots' error bars; the table's are differences)
           "ci95": {label: np.percentile(boot[:, i], [2.5, 97.5]).round(4).tolist() for i, label in enumerate(labels)},
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
            f"{result['resamples']} resamples, seed {result['seed']}): {result['statistic']} sd "
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

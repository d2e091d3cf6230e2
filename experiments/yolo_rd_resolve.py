"""How many maps and seeds the RD tables need before their differences resolve (issue 54):

    python -m experiments.yolo_rd_resolve table3|table4|table5|table6 [--maps 1000] [--out RUN_DIR]
                                          [--small-side 16,16] [--record FILE] [--resamples 1000]

Takes a table's finished rows from the journal `experiments.yolo_rd_tables` wrote (the same --out
and --small-side) and scores each trial's final weights on MAPS held-out test maps
(search.trial.held_out: nothing trains; cached in RUN_DIR/held_out/). The noise in each row's
difference from the first row then has two parts, measured apart:
- evaluation (sd_maps): a paired bootstrap over the maps with every seed kept; it shrinks as
  1/sqrt(maps);
- training (sd_seed): the spread of one row's figure between seeds on all the maps, pooled over
  the rows (a difference of two rows trained apart carries it twice); it shrinks as 1/sqrt(seeds)
  per row, and no number of maps removes it.
The table gives each difference with the interval of the full paired bootstrap (maps and seeds
drawn, search.significance, as the tables' own), the smallest difference N seeds on MAPS maps
resolve at 95 % (1.96 sqrt(sd_maps^2 + 2 sd_seed^2 / N)), and the seeds a row needs before our
gap, and the paper's own gap, between the two rows would resolve at MAPS maps ("more maps" where
sd_maps alone is already too wide).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import math
import shlex
import statistics
import sys
from pathlib import Path

import numpy as np

from dsfec_jax.core import atomic
from dsfec_jax.core.environment import environment
from dsfec_jax.core.provenance import jsonable
from dsfec_jax.metrics.resampling import MatchTable, bootstrap_counts
from dsfec_jax.models.yolo_rd.config import EARLIER_SMALL_SIDE
from search.journal import Journal
from search.significance import RESAMPLES, candidate_tables, paired_bootstrap
from search.trial import held_out

from .yolo_rd_tables import COLUMNS, DEFAULT_OUT, STATISTICS, row_records, small_side_arg, table_rows

Z95 = 1.959964  # the two-sided 95 % normal quantile
SEED_COUNTS = (2, 5, 10, 20)  # the seed counts whose resolvable difference the table prints


def held_out_records(table: str, records: list[dict], run_dir: Path, maps: int, small_side) -> list[tuple]:
    """(label, paper figures, [record with its held-out figures and matches in place of the
    validation's]) of every row with a finished trial, in the table's order."""
    out = []
    for (label, _, ref), recs in zip(table_rows(table), row_records(table, records, small_side)):
        done = [r for r in recs if r["status"] == "ok"]
        if not done:
            continue
        scored = []
        for r in sorted(done, key=lambda r: r["seed"]):
            print(f"{label} (seed {r['seed']}): scoring on {maps} held-out test maps", file=sys.stderr)
            got = held_out(r, run_dir, "test", maps)
            scored.append({**r, "label": label, "metrics": got["metrics"], "matches": got["matches"]})
        out.append((label, ref, scored))
    return out


def row_tables(rows: list[tuple], statistic) -> list[list[dict[str, MatchTable]]]:
    """Each row's match tables as the statistic reads them, one {class: table} per seed."""
    groups = candidate_tables([r for _, _, recs in rows for r in recs], statistic)
    return [groups[label] for label, _, _ in rows]


def seed_values(rows: list[tuple], statistic) -> list[list[float]]:
    """Each row's statistic on all the held-out maps, one value per seed."""
    return [[statistic.value(tables, None) for tables in seeds] for seeds in row_tables(rows, statistic)]


def maps_sd(rows: list[tuple], statistic, resamples: int, seed: int = 0) -> list[float]:
    """sd of each row's difference from the first row over bootstrap draws of the maps alone (every
    seed kept, its values averaged), the evaluation part of the noise."""
    tables = row_tables(rows, statistic)
    frames = len(next(iter(tables[0][0].values())).samples)
    counts = bootstrap_counts(frames, resamples, seed)
    draws = np.array([[np.mean([statistic.value(t, k) for t in seeds]) for k in counts] for seeds in tables])
    return [float(np.std(d - draws[0], ddof=1)) for d in draws]


def pooled_seed_sd(values: list[list[float]]) -> tuple[float | None, int]:
    """The between-seed sd of one row's figure pooled over the rows, and its degrees of freedom."""
    dof = sum(len(v) - 1 for v in values if len(v) > 1)
    if not dof:
        return None, 0
    return math.sqrt(sum((len(v) - 1) * statistics.variance(v) for v in values if len(v) > 1) / dof), dof


def resolvable(sd_maps: float, sd_seed: float, seeds: int) -> float:
    """The smallest difference between two rows of `seeds` seeds each that a 95 % interval separates from 0."""
    return Z95 * math.sqrt(sd_maps ** 2 + 2 * sd_seed ** 2 / seeds)


def seeds_needed(gap: float, sd_maps: float, sd_seed: float) -> int | None:
    """Seeds per row before `gap` resolves at these maps (None: the maps' noise alone is wider)."""
    room = (abs(gap) / Z95) ** 2 - sd_maps ** 2
    if room <= 0:
        return None
    return max(1, math.ceil(2 * sd_seed ** 2 / room))


def resolve(table: str, records: list[dict], run_dir: Path, maps: int, small_side, resamples: int) -> dict:
    headline = COLUMNS[table][-1][0]
    statistic = STATISTICS[headline]
    rows = held_out_records(table, records, run_dir, maps, small_side)
    if len(rows) < 2:
        raise SystemExit(f"{table}: {len(rows)} row(s) with finished trials in {run_dir}; run "
                         f"`python -m experiments.yolo_rd_tables {table} --out {run_dir}` first")
    values = seed_values(rows, statistic)
    sd_m = maps_sd(rows, statistic, resamples)
    sd_s, dof = pooled_seed_sd(values)
    full = paired_bootstrap([r for _, _, recs in rows for r in recs], rows[0][0], resamples, statistic=statistic)
    out_rows = []
    for i, ((label, ref, recs), vals) in enumerate(zip(rows, values)):
        gap = None if ref.get(headline) is None else ref[headline] - rows[0][1][headline]
        row = {"label": label, "paper": ref.get(headline), "paper_gap": gap, "seeds": [r["seed"] for r in recs],
               "per_seed": [round(v, 4) for v in vals], "mean": round(statistics.fmean(vals), 4),
               "trials": [{"key": r["key"], "seed": r["seed"], "held_out": r["metrics"]} for r in recs]}
        if i:
            row.update(delta=round(row["mean"] - statistics.fmean(values[0]), 4), sd_maps=round(sd_m[i], 4),
                       ci95=full["delta"][label]["ci95"])
            if sd_s is not None:
                row["resolvable"] = {str(n): round(resolvable(sd_m[i], sd_s, n), 3) for n in SEED_COUNTS}
                row["seeds_for_our_gap"] = seeds_needed(row["delta"], sd_m[i], sd_s) if row["delta"] else None
                if gap:
                    row["seeds_for_paper_gap"] = seeds_needed(gap, sd_m[i], sd_s)
        out_rows.append(row)
    cost = [r["cpu_s"] for _, _, recs in rows for r in recs if "cpu_s" in r]
    return {"table": table, "statistic": statistic.name, "maps": maps, "split": "test", "resamples": resamples,
            "assign_small_side": list(small_side), "sd_seed": None if sd_s is None else round(sd_s, 4),
            "sd_seed_dof": dof, "trial_cpu_s_median": statistics.median(cost) if cost else None,
            "rows": out_rows, "bootstrap": jsonable(full)}


def markdown(result: dict) -> str:
    seeds = ", ".join(f"{n} seeds" for n in SEED_COUNTS)
    head = (f"| row | {result['statistic']} ours (paper) | Δ vs row 1 [95 % CI] | sd maps | "
            f"resolvable Δ at {seeds} | seeds for our gap | seeds for the paper's gap |")
    lines = [head, "|" + "---|" * 7]
    for row in result["rows"]:
        ours = f"{row['mean']:.1f}" + (f" ± {statistics.stdev(row['per_seed']):.1f}" if len(row["per_seed"]) > 1 else "")
        paper = "-" if row["paper"] is None else row["paper"]
        if "delta" not in row:
            lines.append(f"| {row['label']} | {ours} ({paper}) | | | | | |")
            continue
        lo, hi = row["ci95"]
        verdict = "above noise" if lo > 0 or hi < 0 else "within noise"
        res = " / ".join(f"{v:.1f}" for v in row.get("resolvable", {}).values()) or "-"
        ours_need = _seeds_cell(row.get("seeds_for_our_gap"), bool(row["delta"]) and "resolvable" in row)
        need = _seeds_cell(row.get("seeds_for_paper_gap"), bool(row.get("paper_gap")) and "resolvable" in row)
        gap = "" if row.get("paper_gap") is None else f" (paper {row['paper_gap']:+.1f})"
        lines.append(f"| {row['label']} | {ours} ({paper}) | {row['delta']:+.1f} [{lo:+.1f}, {hi:+.1f}] {verdict}{gap} "
                     f"| {row['sd_maps']:.2f} | {res} | {ours_need} | {need} |")
    sd = "n/a (one seed a row)" if result["sd_seed"] is None else f"{result['sd_seed']:.2f} ({result['sd_seed_dof']} dof)"
    cost = result["trial_cpu_s_median"]
    return ("\n".join(lines) + f"\n\n{result['maps']} held-out test maps, {result['resamples']} resamples; "
            f"between-seed sd of one row's {result['statistic']}, pooled over the rows: {sd}"
            + ("" if cost is None else f"; a trial costs {cost / 60:.0f} CPU min (median)") + ".\n")


def _seeds_cell(seeds: int | None, asked: bool) -> str:
    if not asked:
        return "-"
    return "more maps" if seeds is None else str(seeds)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.yolo_rd_resolve", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("table", choices=sorted(COLUMNS))
    p.add_argument("--maps", type=int, default=1000, help="held-out test maps each trial is scored on (default 1000)")
    p.add_argument("--out", default=DEFAULT_OUT, help=f"the tables' run directory (default {DEFAULT_OUT})")
    p.add_argument("--small-side", type=small_side_arg, default=EARLIER_SMALL_SIDE, metavar="BELOW,WIDENED_TO",
                   help="the small-box rule the rows trained with (as experiments.yolo_rd_tables)")
    p.add_argument("--resamples", type=int, default=RESAMPLES)
    p.add_argument("--record", default=None, help="where the shipped record goes (default: none; RUN_DIR gets "
                                                   "TABLE_resolve.md either way)")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    if not 1 <= args.maps <= 100_000:
        raise SystemExit(f"--maps {args.maps}: expected 1 to 100000")
    result = resolve(args.table, Journal(args.out).records(), Path(args.out), args.maps, args.small_side,
                     args.resamples)
    text = markdown(result)
    atomic.write_text(Path(args.out) / f"{args.table}_resolve.md", text)
    if args.record:
        command = "python -m experiments.yolo_rd_resolve " + " ".join(
            shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
        atomic.write_json(args.record, {"command": command, **result, "markdown": text, "environment": environment()})
        print(f"record: {args.record}")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

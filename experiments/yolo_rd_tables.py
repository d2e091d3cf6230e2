"""The YOLOv8n-Adapter paper's Tables 3-6 on the synthetic RD benchmark, ours beside the paper's:

    python -m experiments.yolo_rd_tables table3|table4|table5|table6 [--profile quick|paper|smoke]
                                         [--seeds 2] [--out RUN_DIR] [--backend ray]
                                         [--record DIR] [--rows LABEL,LABEL]

Table 3: YOLOv8 n/s/m/l and YOLOv8n-Adapter; Table 4: the Adapter on YOLOv8n, YOLOv9t, YOLOv10n;
Table 5: input representations (backbone heat/gray x adapter none/gray/heat); Table 6: fusion
options 1/2/3. Every row is a config of one network family, written as overrides of `yolov8n`, and
trained and measured by one search trial (search/trial.py: fit with the family's recipe, COCO AP
through pycocotools, profile). All four tables share one journal (default
runs/experiments/yolo_rd): a row that two tables hold (YOLOv8n is in all four) trains once, and a
killed run resumes where it stopped.

How much of a difference is noise: every trial keeps its per-sample COCO matches, so the table's
headline column gets a paired bootstrap over the validation samples (search.significance, the
search reports' own): each row's difference from the first row with its 95 % interval, "above
noise" where the interval excludes 0. With --seeds N each row trains N times, the table gives
mean ± sd over seeds, and the bootstrap draws seeds too, so training noise widens the intervals. A
journal from before the matches were kept gains them without training: `python -m search.rescore
RUN_DIR`. The paper's numbers are RADDet's (real data); ours are the synthetic benchmark's, so only
orderings and gaps compare.

Every row pins the assigner's small-box rule in its trial overrides (--small-side, default 8,16:
the rule docs/range-doppler.md's tables were measured with, the family's default before issue 49;
16,16 is ultralytics 8.4.190's, the family's default now), so the command reproduces those tables
and a journal's records say which rule they trained with. Records from before the pin (no
assign_small_side in their overrides) match no row: re-run them.

What ships: RUN_DIR is scratch (runs/ is not in the repository), so each run also writes the
table's record to --record (default experiments/records/yolo_rd/TABLE_PROFILE.json): the command,
every row's trials with their seeds, figures, costs, wall/CPU time and environment (versions), the
bootstrap verdicts and the markdown. Match tables stay in the journal (they are large).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import dataclasses
import shlex
import statistics
import sys
from pathlib import Path

from dsfec_jax.core import atomic
from dsfec_jax.core.provenance import jsonable
from dsfec_jax.models.yolo_rd import paper
from dsfec_jax.models.yolo_rd.config import EARLIER_SMALL_SIDE
from dsfec_jax.models.yolo_rd.variants import (TABLE5_ROWS, TABLE6_OPTIONS, VARIANTS, fusion_variant,
                                               representation_variant)
from dsfec_jax.metrics.boxes2d.coco import COCO_IOU_THRESHOLDS
from search.cli import parse, parser, run_search
from search.journal import Journal
from search.significance import Statistic, paired_bootstrap
from search.significance import summary as significance_note

BASE = "yolov8n"
UNCOMPARED = ("name", "notes")  # config fields that do not change the network or its training
DEFAULT_OUT = "runs/experiments/yolo_rd"
DEFAULT_RECORD_DIR = "experiments/records/yolo_rd"
TRIAL_FIELDS = ("seed", "status", "error", "metrics", "costs", "recipe", "data", "key", "wall_s", "cpu_s",
                "environment")  # what a shipped record keeps of each journal record


def overrides_of(cfg) -> dict:
    """`cfg` as overrides of the base variant (the fields that differ, name and notes aside)."""
    base = VARIANTS[BASE]
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)
            if f.name not in UNCOMPARED and getattr(cfg, f.name) != getattr(base, f.name)}


def row_overrides(cfg, small_side=EARLIER_SMALL_SIDE) -> dict:
    """A row's trial overrides: `cfg`'s overrides of the base, the small-box rule always pinned."""
    return {**overrides_of(cfg), "assign_small_side": tuple(float(v) for v in small_side)}


def small_side_arg(text: str) -> tuple[float, float]:
    """--small-side BELOW,WIDENED_TO (pixels)."""
    try:
        below, widened_to = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected BELOW,WIDENED_TO in pixels (8,16 or 16,16); got {text!r}") from None
    return below, widened_to


def canonical_label(cfg, fallback: str) -> str:
    """The zoo name of the variant `cfg` equals (so rows shared by tables share a trial), else `fallback`."""
    same = [name for name, v in VARIANTS.items() if overrides_of(v) == overrides_of(cfg)]
    return same[0] if same else fallback


def table_rows(table: str) -> list[tuple[str, object, dict]]:
    """(label, config, the paper's RADDet figures) of each row, in the paper's order."""
    if table == "table3":
        return [(n, VARIANTS[n], paper.TABLE3["RADDet"][n]) for n in ("yolov8n", "yolov8s", "yolov8m", "yolov8l",
                                                                       "yolov8n_adapter")]
    if table == "table4":
        return [(n, VARIANTS[n], paper.TABLE4["RADDet"][n]) for n in paper.TABLE4["RADDet"]]
    if table == "table5":
        out = []
        for backbone, adapter in TABLE5_ROWS:
            cfg = representation_variant(backbone, adapter)
            label = canonical_label(cfg, f"yolov8n_adapter backbone={backbone} adapter={adapter}")
            out.append((label, cfg, {"mAP50_95": paper.TABLE5["RADDet"][(backbone, adapter)],
                                     "backbone": backbone, "adapter": adapter or "-"}))
        return out
    if table == "table6":
        return [(canonical_label(fusion_variant(o), f"yolov8n_adapter fusion={o}"), fusion_variant(o),
                 {**paper.TABLE6["RADDet"][o], "fusion": o}) for o in TABLE6_OPTIONS]
    raise SystemExit(f"unknown table {table!r}; expected table3, table4, table5 or table6")


STATISTICS = {  # a headline column -> the bootstrap's statistic over every class's match table
    "mAP50": Statistic("mAP@50", None, (0.5,)),
    "mAP50_95": Statistic("mAP@50-95", None, tuple(float(t) for t in COCO_IOU_THRESHOLDS)),
}

COLUMNS = {  # table -> (record key, title); each printed as "ours (paper)"; the last is the headline
    "table3": (("params", "Params (M)"), ("mAP50", "mAP@50"), ("mAP50_95", "mAP@50-95")),
    "table4": (("params", "Params (M)"), ("mAP50", "mAP@50"), ("mAP50_95", "mAP@50-95")),
    "table5": (("mAP50_95", "mAP@50-95"),),
    "table6": (("mAP50", "mAP@50"), ("mAP70", "mAP@70"), ("mAP50_95", "mAP@50-95")),
}


def _value(record: dict, key: str):
    if key == "params":
        return record["costs"]["params"] / 1e6
    return record["metrics"].get(key)


def _stats(records: list[dict], key: str) -> tuple[float | None, float, int]:
    vals = [v for v in (_value(r, key) for r in records if r["status"] == "ok") if v is not None]
    if not vals:
        return None, 0.0, 0
    return statistics.fmean(vals), statistics.stdev(vals) if len(vals) > 1 else 0.0, len(vals)


def _bootstrap(table: str, rows: list, found: list[list[dict]]) -> dict | None:
    """The paired bootstrap of the headline over the rows that have match tables (None without)."""
    relabelled = [{**r, "label": label} for (label, _, _), recs in zip(rows, found) for r in recs]
    if not found or not found[0] or not relabelled:
        return None
    try:
        return paired_bootstrap(relabelled, rows[0][0], statistic=STATISTICS[COLUMNS[table][-1][0]])
    except ValueError as err:  # rows scored on other frames: the table stands without intervals
        print(f"no bootstrap intervals: {err}", file=sys.stderr)
        return None


def _delta(label: str, mean, first, sig: dict | None) -> str:
    if mean is None or first is None:
        return "-"
    d = (sig or {}).get("delta", {}).get(label)
    if d is None:
        return f"{mean - first:+.1f}"
    lo, hi = d["ci95"]
    return f"{mean - first:+.1f} [{lo:+.1f}, {hi:+.1f}]" + (" above noise" if lo > 0 or hi < 0 else " within noise")


def markdown(table: str, records: list[dict], small_side=EARLIER_SMALL_SIDE) -> str:
    """The table: per row ours (mean ± sd over seeds) beside the paper's, and the headline's change
    from the first row with its 95 % paired-bootstrap interval over validation samples (and seeds);
    the rows trained with the small-box rule `small_side`."""
    rows = table_rows(table)
    headline = COLUMNS[table][-1][0]
    found = [[r for r in recs if r["status"] == "ok"] for recs in row_records(table, records, small_side)]
    sig = _bootstrap(table, rows, found)
    first = _stats(found[0], headline)[0] if found else None
    extra = [k for k in ("backbone", "adapter", "fusion") if k in rows[0][2]]
    interval = " [95 % CI]" if sig is not None and "delta" in sig else ""
    head = ["row"] + extra + [f"{t} ours (paper)" for _, t in COLUMNS[table]] + ["seeds",
                                                                                f"Δ {headline} vs row 1{interval}"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for (label, _, ref), recs in zip(rows, found):
        cells = [label] + [str(ref[k]) for k in extra]
        for key, _ in COLUMNS[table]:
            mean, sd, n = _stats(recs, key)
            ours = "-" if mean is None else f"{mean:.{3 if key == 'params' else 1}f}" + (f" ± {sd:.1f}" if n > 1 else "")
            cells.append(f"{ours} ({ref.get(key, '-')})")
        mean, _, n = _stats(recs, headline)
        cells += [str(n), _delta(label, mean, first, sig)]
        lines.append("| " + " | ".join(cells) + " |")
    if sig is not None:
        note = significance_note(sig)
    else:
        note = ("No intervals: the rows' records keep no match tables (a journal from before they were kept: "
                "`python -m search.rescore RUN_DIR` adds them without training).")
    return "\n".join(lines) + "\n\n" + note + "\n"


def table_record(table: str, records: list[dict], command: str, profile: str, small_side=EARLIER_SMALL_SIDE) -> dict:
    """The shipped record of one table: each row's trials (seeds, figures, costs, time, versions),
    the bootstrap verdicts and the markdown, so docs/range-doppler.md's figures are traceable without runs/."""
    rows = table_rows(table)
    found = row_records(table, records, small_side)
    sig = _bootstrap(table, rows, [[r for r in recs if r["status"] == "ok"] for recs in found])
    return {"table": table, "command": command, "profile": profile, "assign_small_side": list(small_side),
            "complete": all(any(r["status"] == "ok" for r in recs) for recs in found),
            "rows": [{"label": label, "overrides": row_overrides(cfg, small_side), "paper_raddet": jsonable(ref),
                      "trials": [{k: r[k] for k in TRIAL_FIELDS if k in r} for r in recs]}
                     for (label, cfg, ref), recs in zip(rows, found)],
            "bootstrap": jsonable(sig), "markdown": markdown(table, records, small_side)}


def row_records(table: str, records: list[dict], small_side=EARLIER_SMALL_SIDE) -> list[list[dict]]:
    """Each row's journal records (every seed, failed ones too), in the table's row order."""
    by_key = {}
    for r in records:
        by_key.setdefault(_row_key(r["overrides"]), []).append(r)
    return [by_key.get(_row_key(row_overrides(cfg, small_side)), []) for _, cfg, _ in table_rows(table)]


def _row_key(overrides: dict) -> str:
    return repr(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in overrides.items()))


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-"):
        raise SystemExit(__doc__)
    table, rest = argv[0], argv[1:]
    rows = table_rows(table)
    p = parser(f"python -m experiments.yolo_rd_tables {table}", __doc__, base=BASE)
    p.add_argument("--small-side", type=small_side_arg, default=EARLIER_SMALL_SIDE, metavar="BELOW,WIDENED_TO",
                   help="the assigner's small-box rule every row trains with (default 8,16: the README's tables; "
                        "16,16: ultralytics 8.4.190's)")
    p.add_argument("--record", default=DEFAULT_RECORD_DIR,
                   help=f"where the table's shipped record goes (default {DEFAULT_RECORD_DIR})")
    p.add_argument("--rows", default=None, metavar="LABEL,LABEL",
                   help="train only these rows (labels as the table prints them; default every row): "
                        "table3 --rows yolov8n,yolov8n_adapter skips the s/m/l scales")
    args = parse(p, rest)
    args.out = args.out or DEFAULT_OUT
    wanted = None if args.rows is None else set(args.rows.split(","))
    unknown = sorted((wanted or set()) - {label for label, _, _ in rows})
    if unknown:
        raise SystemExit(f"--rows: no row {unknown} in {table}; its rows: {[label for label, _, _ in rows]}")

    def build():
        seen, out = set(), []
        for label, cfg, _ in rows:
            overrides = row_overrides(cfg, args.small_side)
            if _row_key(overrides) not in seen and (wanted is None or label in wanted):
                seen.add(_row_key(overrides))
                out.append({"label": label, "overrides": overrides})
        return out

    run_search(args, f"yolo_rd_{table}", build, f"YOLO-RD {table} (synthetic RD benchmark)", BASE)
    records = Journal(args.out).records()
    text = markdown(table, records, args.small_side)
    rule = "small boxes: sides under {:g} px -> {:g} px".format(*args.small_side)
    atomic.write_text(Path(args.out) / f"{table}.md", f"### {table} ({args.profile} profile, {rule})\n\n{text}")
    command = f"python -m experiments.yolo_rd_tables {table} " + " ".join(shlex.quote(a) for a in rest)
    record_path = Path(args.record) / f"{table}_{args.profile}.json"
    atomic.write_json(record_path, table_record(table, records, command.strip(), args.profile, args.small_side))
    print(text)
    print(f"record: {record_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

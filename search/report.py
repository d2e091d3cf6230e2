"""Ablation reports from a journal: Markdown and CSV tables laid out like the DSFEC paper's
(each cell of the non-base rows carries its change against the base row, e.g. "1027 (-109)"),
the JSON records, and PNG plots of mAP against GFLOPs and latency with the Pareto front.

    python -m search.report RUN_DIR
"""

from __future__ import annotations

import csv
import io
import json
import statistics
import sys
from collections import defaultdict
from pathlib import Path

from dsfec_jax import zoo
from dsfec_jax.core import atomic, spread

from . import seed_agreement, significance
from .journal import Journal

def protocol(records: list[dict]):
    """The metric protocol of the family the trials' base belongs to (models.family.MetricProtocol):
    its columns lay out the tables (first = the headline), its `match_class` asks for bootstrap
    intervals and its `zero_class_note` for the note on classes scoring 0 everywhere."""
    bases = {r.get("base") for r in records}
    if len(bases) != 1 or None in bases:
        raise ValueError(f"journal records name bases {sorted(map(str, bases))}; expected one registered model "
                         "(every trial record carries its 'base')")
    return zoo.family_of(bases.pop()).metric


def columns_for(records: list[dict]) -> tuple:
    """(record key, column title, digits) of the report's columns."""
    return protocol(records).columns


def headline(records: list[dict]) -> tuple[str, str]:
    """(record key, title) of the figure candidates are ranked and plotted by."""
    key, title, _ = columns_for(records)[0]
    return key, title


def rows(records: list[dict], columns: tuple | None = None) -> list[dict]:
    """One row per candidate (label), seeds aggregated to mean and spread; failed trials listed."""
    columns = columns or columns_for(records)
    groups = defaultdict(list)
    for r in records:
        groups[r["label"]].append(r)
    out = []
    for label, recs in groups.items():
        ok = [r for r in recs if r["status"] == "ok"]
        row = {"label": label, "seeds": len(recs), "failed": len(recs) - len(ok),
               "errors": [r["error"] for r in recs if r["status"] != "ok"]}
        for key, _, _ in columns:
            if key == "latency_ms":
                row.update(latency_spread(ok))
                continue
            vals = [_value(r, key) for r in ok]
            vals = [v for v in vals if v is not None]
            row[key] = statistics.fmean(vals) if vals else None
            row[key + "_sd"] = statistics.stdev(vals) if len(vals) > 1 else 0.0
        out.append(row)
    return out


def latency_spread(ok: list[dict]) -> dict:
    """A candidate's latency: the median of its measured medians, with the spread over the timing
    loop's repeats (the lowest 10th and highest 90th percentile of its measurements) and the
    machine's verdict while it was timed. Not a spread over seeds: `--seeds N` profiles a
    candidate once and the other seeds copy its costs ("costs_from"), so a standard deviation over
    seeds is 0 whatever the noise (issue 51's latency column)."""
    own = [r["costs"] for r in ok if "costs_from" not in r and r.get("costs", {}).get("latency_ms") is not None]
    if not own:
        return {"latency_ms": None, "latency_ms_sd": None, "latency_ms_p10": None, "latency_ms_p90": None,
                "latency_busy": None}
    p10 = [c["latency_p10_ms"] for c in own if c.get("latency_p10_ms") is not None]
    p90 = [c["latency_p90_ms"] for c in own if c.get("latency_p90_ms") is not None]
    busy = [c["machine_load"]["text"] for c in own if (c.get("machine_load") or {}).get("busy")]
    return {"latency_ms": statistics.median(c["latency_ms"] for c in own), "latency_ms_sd": None,
            "latency_ms_p10": min(p10) if p10 else None, "latency_ms_p90": max(p90) if p90 else None,
            "latency_busy": busy[0] if busy else None}


def _value(record: dict, key: str):
    if key in record.get("metrics", {}):
        return record["metrics"][key]
    v = record.get("costs", {}).get(key)
    return v / 1e6 if key == "params" and v is not None else v


SIZE_KEYS = ("gflops", "params", "memory_mb")  # counted from the architecture: the same for every seed


def _cell(row, base, key, digits) -> str:
    v = row[key]
    if v is None:
        return "failed" if row["failed"] else "-"
    if key == "latency_ms":  # the spread over the timing loop's repeats, not over seeds
        text = spread.text(v, row.get("latency_ms_p10"), row.get("latency_ms_p90"), digits)
    elif key in SIZE_KEYS:  # a property of the architecture: seeds cannot spread it
        text = f"{v:.{digits}f}"
    else:
        text = f"{v:.{digits}f}" + (f" ± {row[key + '_sd']:.{digits}f}" if row["seeds"] > 1 else "")
    if base is not None and row is not base and base[key] is not None:
        text += f" ({v - base[key]:+.{digits}f})"
    return text


def _interval(sig: dict | None, label: str) -> list[str]:
    """The bootstrap column's cell: the 95 % interval of the Car-mAP difference from the base."""
    if sig is None or "delta" not in sig:
        return []
    d = sig["delta"].get(label)
    return ["-" if d is None else f"[{d['ci95'][0]:+.2f}, {d['ci95'][1]:+.2f}]"]


def markdown(table: list[dict], base_label: str | None, title: str, columns: tuple,
             sig: dict | None = None) -> str:
    """The table; with `sig` (search.significance) a column of bootstrap intervals and its summary."""
    base = next((r for r in table if r["label"] == base_label), None)
    head = ["candidate"] + [name for _, name, _ in columns]
    if sig is not None and "delta" in sig:
        head.insert(2, f"Δ {sig['statistic']} 95 % CI (frames" + (", seeds)" if sig.get("seeds", 1) > 1 else ")"))
    lines = [f"### {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in table:
        mark = " (base)" if r is base else ""
        cells = [_cell(r, base, k, d) for k, _, d in columns]
        lines.append("| " + " | ".join([r["label"] + mark] + cells[:1] + _interval(sig, r["label"]) + cells[1:]) + " |")
    for r in table:
        for err in r["errors"]:
            lines.append(f"\nFailed: {r['label']}: {err}")
    if any(k == "latency_ms" for k, _, _ in columns):
        lines.append("\nLatency: median over the timing loop's repeats, (p10-p90) beside it.")
        busy = [r for r in table if r.get("latency_busy")]
        if busy:
            lines.append(f"Timed on a busy machine ({busy[0]['latency_busy']}): the latencies of "
                         f"{', '.join(r['label'] for r in busy)} are not the machine's; their order is noise.")
    if sig is not None:
        lines.append("\n" + significance.summary(sig))
    return "\n".join(lines) + "\n"


def zero_classes(records: list[dict]) -> list[str]:
    """Classes whose nuScenes mAP is 0 in every finished trial: "mAP (4 classes)" still averages
    them in, so the report names them beside the table (the column is then mostly the others')."""
    maps = [r["metrics"]["class_mAP"] for r in records
            if r["status"] == "ok" and isinstance(r.get("metrics", {}).get("class_mAP"), dict)]
    if not maps:
        return []
    return [c for c in maps[0] if all(m.get(c) == 0.0 for m in maps)]


def zero_class_note(records: list[dict]) -> str:
    zero = zero_classes(records)
    if not zero:
        return ""
    return (f"\n\"mAP (4 classes)\" averages the class mAPs of {', '.join(records_classes(records))}; "
            f"{' and '.join(zero)} score{'s' if len(zero) == 1 else ''} 0.0 in every candidate, "
            "so that column moves only with the other classes.\n")


def records_classes(records: list[dict]) -> list[str]:
    return next((list(r["metrics"]["class_mAP"]) for r in records
                 if isinstance(r.get("metrics", {}).get("class_mAP"), dict)), [])


def provenance(records: list[dict], meta: dict) -> str:
    """How the table was measured: strategy, recipe, training cost, the command."""
    ok = [r for r in records if r["status"] == "ok"]
    strategy = meta.get("strategy") or (records[0].get("strategy", "train"))
    wall = sum(r.get("wall_s", 0) for r in records)
    line = f"Profile `{meta.get('profile', records[0].get('recipe'))}`, strategy `{strategy}`"
    nets = {}  # (depth, steps) -> {seed: wall s}: one supernet per seed
    for r in ok:
        if "supernet" in r:
            n = r["supernet"]
            depth = next(tuple(v) for k, v in n.items() if k not in ("steps", "wall_s", "cpu_s"))  # e.g. stage_blocks
            nets.setdefault((depth, n["steps"]), {})[r.get("seed", 0)] = n["wall_s"]
    for (blocks, steps), walls in nets.items():
        times = ", ".join(f"{walls[s]:.0f} s" for s in sorted(walls))
        line += f"; supernet {blocks} trained {steps} steps in {times}" + (
            f" (seeds {', '.join(map(str, sorted(walls)))})" if len(walls) > 1 else "")
    inits = sorted({r.get("init", "scratch") for r in records})
    line += "; started from " + ", ".join("scratch" if i == "scratch" else f"the shipped `{i}` (elastic depth: each "
                                          "candidate keeps the first k blocks; favours the base's depth)"
                                          for i in inits)
    line += f"; {len(records)} trial records, {wall / 60:.1f} min of trial wall time."
    return "\n" + line + "\n" + (f"\nCommand: `{meta['command']}`\n" if meta.get("command") else "")


def csv_text(table: list[dict], columns: tuple) -> str:
    buf = io.StringIO()
    keys = ["label", "seeds", "failed"] + [k for key, _, _ in columns for k in
                                            ((key, key + "_p10", key + "_p90") if key == "latency_ms" else (key, key + "_sd"))]
    writer = csv.DictWriter(buf, keys, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(table)
    return buf.getvalue()


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points no other point beats on both lower cost and higher score."""
    return [i for i, (c, s) in enumerate(points)
            if not any((c2 <= c and s2 >= s) and (c2 < c or s2 > s) for c2, s2 in points)]


COST_TITLES = {"gflops": "GFLOPs (2 x MAC, batch 1)", "latency_ms": "latency (ms, batch 1, CPU; median, whisker p10-p90)"}


def score_errors(table: list[dict], key: str, sig: dict | None) -> tuple[list, str | None]:
    """Per-row (below, above) error of the plotted score and what it is: the bootstrap 95 %
    interval of the headline (search.significance: 'ci95'), else +- the seeds' standard deviation,
    else none."""
    ci = (sig or {}).get("ci95", {})
    if sig and sig.get("statistic") and all(r["label"] in ci for r in table):
        return ([(max(r[key] - ci[r["label"]][0], 0.0), max(ci[r["label"]][1] - r[key], 0.0)) for r in table],
                "bootstrap 95 % interval")
    if any(r["seeds"] > 1 for r in table):
        return [(r.get(key + "_sd") or 0.0,) * 2 for r in table], "+- seeds' standard deviation"
    return [(0.0, 0.0)] * len(table), None


def plot(table: list[dict], cost: str, path: Path, title: str, score: tuple[str, str] = ("car_mAP", "Car mAP"),
         sig: dict | None = None) -> None:
    """`figure` written to `path` as a PNG."""
    save_figure(figure(table, cost, title, score, sig), path)


def figure(table: list[dict], cost: str, title: str, score: tuple[str, str] = ("car_mAP", "Car mAP"),
           sig: dict | None = None):
    """mAP against a cost, each candidate with its error bars (the score's interval; the latency's
    p10-p90), labelled clear of each other; the Pareto front in red, its line drawn only through two
    or more points (one point is no front); a warning on the plot when the latency was timed on a
    busy machine."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from . import plot_labels

    key, name = score
    rows_ = [r for r in table if r[cost] is not None and r[key] is not None]
    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=120)
    if rows_:
        pts = [(r[cost], r[key]) for r in rows_]
        front = set(pareto(pts))
        yerr, yerr_kind = score_errors(rows_, key, sig)
        xerr = ([(r[cost] - (r.get("latency_ms_p10") or r[cost]), (r.get("latency_ms_p90") or r[cost]) - r[cost])
                 for r in rows_] if cost == "latency_ms" else None)
        for on_front, colour, label in ((False, "tab:blue", "candidate"), (True, "tab:red", "on the Pareto front")):
            idx = [i for i in range(len(rows_)) if (i in front) == on_front]
            if not idx:
                continue
            ax.errorbar([pts[i][0] for i in idx], [pts[i][1] for i in idx],
                        yerr=[[yerr[i][0] for i in idx], [yerr[i][1] for i in idx]] if yerr_kind else None,
                        xerr=[[xerr[i][0] for i in idx], [xerr[i][1] for i in idx]] if xerr else None,
                        fmt="o", color=colour, ecolor=colour, elinewidth=0.8, capsize=2, ms=5, zorder=3, label=label)
        if len(front) >= 2:
            fr = sorted(pts[i] for i in front)
            ax.plot([c for c, _ in fr], [s for _, s in fr], color="tab:red", lw=1, zorder=2, label="Pareto front")
        notes = [f"error bars: {yerr_kind}"] if yerr_kind else []
        if cost == "latency_ms" and any(r.get("latency_busy") for r in rows_):
            notes.append("timed on a busy machine: latency order is noise")
        if notes:
            ax.set_title(title + "\n" + "; ".join(notes), fontsize=8)
        else:
            ax.set_title(title, fontsize=9)
        ax.margins(x=0.15, y=0.15)  # room for the labels beside the outermost points
        ax.legend(fontsize=7, loc="best")
    else:
        ax.set_title(title, fontsize=9)
    ax.set_xlabel(COST_TITLES[cost])
    ax.set_ylabel(f"{name} (%)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    if rows_:
        plot_labels.place(ax, [(c, s, r["label"]) for (c, s), r in zip(pts, rows_)])
    return fig


def save_figure(fig, path: Path) -> None:
    """A matplotlib figure as a PNG, written atomically, then closed."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic.write_bytes(path, buf.getvalue())


def write_reports(run_dir: str | Path) -> dict:
    """Regenerate every report of RUN_DIR from its journal (and search.json, if present)."""
    run_dir = Path(run_dir)
    records = Journal(run_dir).records()
    if not records:
        raise ValueError(f"{run_dir}: no journal records to report")
    meta_path = run_dir / "search.json"
    meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
    metric = protocol(records)
    columns = metric.columns
    table = rows(records, columns)
    title = meta.get("title", "ablation")
    try:
        sig = significance.paired_bootstrap(records, meta.get("base_label"),
                                            statistic=significance.Statistic.of(metric)) if metric.match_class else None
    except ValueError as err:  # e.g. a resumed journal whose trials saw other frames: the tables still matter
        sig, note = None, f"\nNo bootstrap intervals: {err}\n"
    else:
        note = ""
    score = headline(records)
    seeds = seed_agreement.agreement(records, score[0])
    if seeds is not None:
        note += "\n" + seed_agreement.summary(seeds, score[1]) + "\n"
    files = ["report.md", "report.csv", "records.json", "map_vs_gflops.png", "map_vs_latency.png"]
    atomic.write_text(run_dir / "report.md",
                      markdown(table, meta.get("base_label"), title, columns, sig) + note
                      + (zero_class_note(records) if metric.zero_class_note else "") + provenance(records, meta))
    atomic.write_text(run_dir / "report.csv", csv_text(table, columns))
    # the match tables stay in the journal: records.json is for reading
    atomic.write_json(run_dir / "records.json", [{k: v for k, v in r.items() if k != "matches"} for r in records])
    if sig is not None:
        atomic.write_json(run_dir / "significance.json", sig)
        files.append("significance.json")
    else:  # an earlier report's intervals no longer describe this journal
        (run_dir / "significance.json").unlink(missing_ok=True)
    if seeds is not None:
        atomic.write_json(run_dir / "seed_agreement.json", seeds)
        files.append("seed_agreement.json")
    else:
        (run_dir / "seed_agreement.json").unlink(missing_ok=True)
    # the plots' error bars are the headline's bootstrap intervals: only when the bootstrap scores it
    plotted_sig = sig if sig is not None and sig.get("statistic") == score[1] else None
    plot(table, "gflops", run_dir / "map_vs_gflops.png", title, score, plotted_sig)
    plot(table, "latency_ms", run_dir / "map_vs_latency.png", title, score, plotted_sig)
    return {"rows": table, "files": files, "significance": sig, "seed_agreement": seeds}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        sys.exit("usage: python -m search.report RUN_DIR")
    out = write_reports(argv[0])
    print((Path(argv[0]) / "report.md").read_text())
    print("wrote " + ", ".join(out["files"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

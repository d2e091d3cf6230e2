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
from dsfec_jax.core import atomic

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
            vals = [_value(r, key) for r in ok]
            vals = [v for v in vals if v is not None]
            row[key] = statistics.fmean(vals) if vals else None
            row[key + "_sd"] = statistics.stdev(vals) if len(vals) > 1 else 0.0
        out.append(row)
    return out


def _value(record: dict, key: str):
    if key in record.get("metrics", {}):
        return record["metrics"][key]
    v = record.get("costs", {}).get(key)
    return v / 1e6 if key == "params" and v is not None else v


def _cell(row, base, key, digits) -> str:
    v = row[key]
    if v is None:
        return "failed" if row["failed"] else "-"
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
    keys = ["label", "seeds", "failed"] + [k for key, _, _ in columns for k in (key, key + "_sd")]
    writer = csv.DictWriter(buf, keys, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(table)
    return buf.getvalue()


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points no other point beats on both lower cost and higher score."""
    return [i for i, (c, s) in enumerate(points)
            if not any((c2 <= c and s2 >= s) and (c2 < c or s2 > s) for c2, s2 in points)]


def plot(table: list[dict], cost: str, path: Path, title: str, score: tuple[str, str] = ("car_mAP", "Car mAP")) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key, name = score
    pts = [(r[cost], r[key], r["label"]) for r in table if r[cost] is not None and r[key] is not None]
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=120)
    if pts:
        front = set(pareto([(c, s) for c, s, _ in pts]))
        for i, (c, s, label) in enumerate(pts):
            ax.scatter(c, s, color="tab:red" if i in front else "tab:blue", zorder=3)
            ax.annotate(label, (c, s), fontsize=7, xytext=(3, 3), textcoords="offset points")
        fr = sorted((pts[i][0], pts[i][1]) for i in front)
        ax.plot([c for c, _ in fr], [s for _, s in fr], color="tab:red", lw=1, label="Pareto front")
        ax.legend(fontsize=8)
    ax.set_xlabel({"gflops": "GFLOPs (2 x MAC, batch 1)", "latency_ms": "latency (ms, batch 1, CPU)"}[cost])
    ax.set_ylabel(f"{name} (%)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


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
    plot(table, "gflops", run_dir / "map_vs_gflops.png", title, score)
    plot(table, "latency_ms", run_dir / "map_vs_latency.png", title, score)
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

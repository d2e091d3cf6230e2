"""What a NAS run reports: the generation table, the top subnets, Pareto plots like the paper's
Fig. 5 (accuracy against params and GFLOPs, every scored subnet, the front in red, the zoo's
hand-designed models as reference points), written beside the journal with atomic writes."""

from __future__ import annotations

import json
from pathlib import Path

from dsfec_jax.core import atomic

from ..report import pareto, save_figure

COST_LABELS = {"params": "params (M, BN-folded)", "gflops": "GFLOPs (2 x MAC, batch 1)",
               "latency_ms": "latency (ms, the table's prediction)"}


def cost_cells(costs: dict) -> str:
    """params (M) | GFLOPs | latency (ms, '-' where no latency table was used)."""
    latency = costs.get("latency_ms")
    return (f"{costs['params'] / 1e6:.3f} | {costs['gflops']:.3f} | "
            f"{'-' if latency is None else f'{latency:.1f}'}")


def top_table(records: list[dict], metric: str, k: int = 5) -> str:
    best = sorted(records, key=lambda r: (-r[metric], r["key"]))[:k]
    lines = [f"| rank | subnet | {metric} | params (M) | GFLOPs | latency (ms) | choices |", "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(best, 1):
        choices = ", ".join(f"{n}={v}" for n, v in r["choices"].items())
        lines.append(f"| {i} | {r['key']} | {r[metric]:.2f} | {cost_cells(r['costs'])} | {choices} |")
    return "\n".join(lines)


def reference_table(references: list[dict], metric: str) -> str:
    """The hand-designed reference points of the Pareto plots as a table (inherited or shipped
    scores, as each label says)."""
    lines = [f"| reference | {metric} | params (M) | GFLOPs | latency (ms) |", "|---|---|---|---|---|"]
    for ref in references:
        lines.append(f"| {ref['label']} | {ref[metric]:.2f} | {cost_cells(ref)} |")
    return "\n".join(lines)


def plot_pareto(records: list[dict], cost: str, metric: str, path: Path, title: str,
                references: list[dict] = ()) -> None:
    """`pareto_figure` written to `path` as a PNG."""
    save_figure(pareto_figure(records, cost, metric, title, references), path)


def pareto_figure(records: list[dict], cost: str, metric: str, title: str, references: list[dict] = ()):
    """Every scored subnet (blue), its Pareto front (red; a line only through two or more points)
    and reference models (black squares: {'label', cost, metric}), their labels kept inside the
    axes and clear of each other (search/plot_labels.py)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .. import plot_labels

    scale = 1e-6 if cost == "params" else 1.0
    pts = [(r["costs"][cost] * scale, r[metric]) for r in records]
    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=120)
    if pts:
        ax.scatter([c for c, _ in pts], [s for _, s in pts], s=10, color="tab:blue", alpha=0.5, label="subnets (inherited weights)")
        front = sorted(pts[i] for i in pareto(pts))
        ax.plot([c for c, _ in front], [s for _, s in front], color="tab:red", marker="o", ms=3,
                lw=1 if len(front) > 1 else 0, label="Pareto front" if len(front) > 1 else "best subnet (no front)")
    refs = [(ref[cost] * scale, ref[metric], ref["label"]) for ref in references
            if ref.get(metric) is not None and ref.get(cost) is not None]
    if refs:
        ax.scatter([c for c, _, _ in refs], [s for _, s, _ in refs], marker="s", color="black", zorder=4,
                   label="hand-designed models")
    ax.set_xlabel(COST_LABELS[cost])
    ax.set_ylabel(f"{metric} (%)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.margins(x=0.12, y=0.12)  # room for the labels beside the outermost points
    ax.legend(fontsize=7)
    fig.tight_layout()
    plot_labels.place(ax, refs)
    return fig


def write_report(run_dir: Path, header: str, progress: str, records: list[dict], metric: str,
                 references: list[dict], meta: dict, standalone: str | None = None) -> Path:
    """report.md and the Pareto plots; `standalone`: the stand-alone retraining section, if run."""
    costs = [c for c in COST_LABELS if records and all(c in r["costs"] for r in records)]
    for cost in costs:
        plot_pareto(records, cost, metric, run_dir / f"pareto_{cost}.png", f"{meta['space']}: {metric} vs {cost}",
                    references)
    text = "\n\n".join([header, "## Generations", progress, "## Top subnets (inherited weights)",
                        top_table(records, metric),
                        *(["## Hand-designed reference points", reference_table(references, metric)] if references else []),
                        "Pareto plots: " + ", ".join(f"`pareto_{c}.png`" for c in costs) + ".",
                        *(["## Stand-alone retraining and the ranking study", standalone] if standalone else []),
                        "## Provenance", "```json\n" + json.dumps(meta, indent=1) + "\n```", ""])
    path = run_dir / "report.md"
    atomic.write_text(path, text)
    return path

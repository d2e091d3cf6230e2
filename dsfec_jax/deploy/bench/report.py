"""What `dsfec bench` shows: the markdown table, the ratios worth quoting, the stacked-bar plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core import spread

# (model, its base) -> the ratio's label: what a variant costs over the model it extends
PAIRS = {("dsfec_s", "baseline"): "DSFEC-S / Baseline", ("yolov8n_adapter", "yolov8n"): "YOLOv8n-Adapter / YOLOv8n",
         ("shuffle_yolov3", "yolov3_darknet53"): "Shuffle-YOLOv3 / Darknet53-YOLOv3"}


def stages_of(records: list[dict]) -> list[str]:
    """Every stage the records time, in first-seen order (point and RD models have their own)."""
    return list(dict.fromkeys(s for r in records for s in r["stages_ms"]))


def ratios(records: list[dict]) -> list[str]:
    """The figures to quote: a variant / its base per runtime, JAX / ONNX Runtime and ONNX Runtime
    INT8 / FP32 per model."""
    by = {(r["model"], r["runtime"], r["threads"]): r["total_ms"] for r in records}
    lines = []
    for (m, rt, t), ms in sorted(by.items()):
        threads = f"{t} thread{'s' * (t > 1)}"
        for (variant, base), label in PAIRS.items():
            if m == variant and (base, rt, t) in by:
                lines.append(f"{label} ({rt}, {threads}): {ms / by[(base, rt, t)]:.3f}")
        if rt == "jax" and (m, "onnx", t) in by:
            lines.append(f"JAX / ONNX Runtime ({m}, {threads}): {ms / by[(m, 'onnx', t)]:.3f}")
        if rt == "onnx-int8" and (m, "onnx", t) in by:
            lines.append(f"ONNX Runtime INT8 / FP32 ({m}, {threads}): {ms / by[(m, 'onnx', t)]:.3f}")
    return lines


def stage_cell(r: dict, stage: str) -> str:
    """A stage's median ms with its p10-p90 spread over the repeats ('-' for a stage the chain lacks)."""
    if stage not in r["stages_ms"]:
        return "-"
    low, high = r.get("stages_p10_p90_ms", {}).get(stage, (None, None))
    return spread.text(r["stages_ms"][stage], low, high, digits=2)


def throughput_cell(r: dict) -> str:
    tp, band = r.get("throughput_fps"), r.get("throughput_fps_p10_p90", {})
    if not tp:
        return "-"
    return ", ".join(f"{b}: {v}" + (f" ({band[b][0]}-{band[b][1]})" if b in band else "") for b, v in tp.items())


def machine_notes(records: list[dict]) -> list[str]:
    """One line per worker (thread count) whose timing ran on a busy machine."""
    busy = {r["threads"]: r["machine"] for r in records if (r.get("machine") or {}).get("busy")}
    return [f"Warning: the machine was busy while the {t}-thread worker timed ({v['text'][len('busy: '):]}); "
            "these figures are not the machine's." for t, v in sorted(busy.items())]


def markdown(records: list[dict]) -> str:
    """The table: each figure a median over the repeats with its p10-p90 spread in brackets."""
    stages = stages_of(records)
    head = ["model", "runtime", "threads"] + [f"{s} ms" for s in stages] + ["total ms (p10-p90)", "frames/s (batch 1)",
                                                                          "JAX frames/s by batch (p10-p90)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in records:
        total = spread.text(r["total_ms"], r.get("total_p10_ms"), r["total_p90_ms"])
        lines.append("| " + " | ".join([r["model"], r["runtime"], str(r["threads"])] + [stage_cell(r, s) for s in stages]
                                       + [total, f"{r['fps_batch1']:.1f}", throughput_cell(r)]) + " |")
    env = records[0]
    notes = machine_notes(records)
    return "\n".join(lines + [""] + ratios(records) + ["", f"CPU: {env['cpu']}; versions: {env['versions']}"]
                     + ([""] + notes if notes else [])) + "\n"


def plot(records: list[dict], path: Path) -> None:
    import io

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...core import atomic

    labels = [f"{r['model']}\n{r['runtime']} x{r['threads']}" for r in records]
    fig, ax = plt.subplots(figsize=(max(6, 0.7 * len(records)), 4.2), dpi=120)
    bottom = np.zeros(len(records))
    for stage in stages_of(records):
        vals = np.array([r["stages_ms"].get(stage, 0.0) for r in records])
        ax.bar(labels, vals, bottom=bottom, label=stage)
        bottom += vals
    # the total's spread over the repeats, drawn at the top of each stack (the stages' medians need not
    # sum to the total's median: the bar shows their sum, the whisker the total's p10-p90)
    totals = np.array([r["total_ms"] for r in records])
    low = np.array([r.get("total_p10_ms", r["total_ms"]) for r in records])
    high = np.array([r["total_p90_ms"] for r in records])
    ax.errorbar(labels, bottom, yerr=[np.maximum(totals - low, 0), np.maximum(high - totals, 0)], fmt="none",
                ecolor="black", capsize=3, lw=1, label="total p10-p90")
    ax.set_ylabel("ms, batch 1 (median; whisker p10-p90)")
    busy = any((r.get("machine") or {}).get("busy") for r in records)
    # in the title, where no bar or whisker can run into it
    ax.set_title("raw input -> boxes, per stage" + ("\nthe machine was busy while timing: not the machine's figures"
                                                    if busy else ""), fontsize=10)
    ax.legend(fontsize=7)
    ax.tick_params(axis="x", labelsize=6)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic.write_bytes(path, buf.getvalue())

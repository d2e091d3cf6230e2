"""What `dsfec bench` shows: the markdown table, the ratios worth quoting, the stacked-bar plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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


def markdown(records: list[dict]) -> str:
    stages = stages_of(records)
    head = ["model", "runtime", "threads"] + [f"{s} ms" for s in stages] + ["total ms (p90)", "frames/s (batch 1)",
                                                                          "JAX frames/s by batch"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in records:
        tp = r.get("throughput_fps")
        tp_text = ", ".join(f"{b}: {v}" for b, v in tp.items()) if tp else "-"
        cells = [f"{r['stages_ms'][s]:.2f}" if s in r["stages_ms"] else "-" for s in stages]
        lines.append("| " + " | ".join([r["model"], r["runtime"], str(r["threads"])] + cells
                                       + [f"{r['total_ms']:.1f} ({r['total_p90_ms']:.1f})", f"{r['fps_batch1']:.1f}",
                                          tp_text]) + " |")
    env = records[0]
    return "\n".join(lines + [""] + ratios(records) + ["", f"CPU: {env['cpu']}; versions: {env['versions']}"]) + "\n"


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
    ax.set_ylabel("ms, batch 1 (median)")
    ax.set_title("raw input -> boxes, per stage")
    ax.legend(fontsize=7)
    ax.tick_params(axis="x", labelsize=6)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic.write_bytes(path, buf.getvalue())

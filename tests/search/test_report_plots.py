"""The search reports' latency spread and plots (issue 51): a latency cell carries the timing loop's
p10-p90, never a 0.0 spread over seeds that share one profile; the plots draw error bars, no
one-point "front" line, and labels inside the axes and clear of each other."""

import itertools

import pytest

from search import report
from search.nas import report as nas_report

LATENCY = (457, 225, 258, 377, 195, 275)  # issue 51's stage-2 blocks sweep on a loaded box, 1..6 blocks
CAR_MAP = (31.2, 33.0, 33.4, 33.1, 32.9, 33.3)
BUSY = {"busy": True, "text": "busy: load 3.9 on 2 CPUs"}


def trial(blocks: int, seed: int) -> dict:
    """A one-shot record: the first seed profiles the candidate, the second copies its costs."""
    costs = {"params": 1e6, "gflops": 3.7 + 0.2 * blocks, "memory_mb": 1.0, "latency_ms": LATENCY[blocks - 1],
             "latency_p10_ms": 0.8 * LATENCY[blocks - 1], "latency_p90_ms": 1.35 * LATENCY[blocks - 1],
             "machine_load": BUSY}
    r = {"key": f"{blocks}-{seed}", "base": "dsfec_l", "label": f"stage2_blocks={blocks}", "seed": seed, "status": "ok",
         "metrics": {"car_mAP": CAR_MAP[blocks - 1] + 0.1 * seed, "car_AP4": 0.0, "mAP": 0.0}, "costs": costs}
    return {**r, "costs_from": f"{blocks}-0"} if seed else r


def sweep_table() -> list[dict]:
    return report.rows([trial(b, s) for b in range(1, 7) for s in (0, 1)])


def test_the_latency_cell_is_the_spread_over_repeats_not_over_seeds():
    table = sweep_table()
    assert table[0]["latency_ms"] == 457 and table[0]["latency_ms_p10"] == pytest.approx(365.6)
    md = report.markdown(table, "stage2_blocks=2", "blocks", report.columns_for([trial(1, 0)]))
    row = next(line for line in md.splitlines() if line.startswith("| stage2_blocks=1 "))
    assert row.rstrip(" |").endswith("457.0 (365.6-617.0) (+232.0)"), row  # not "457.0 ± 0.0"
    assert "| 3.90 (-0.20) | 1.000 (+0.000) |" in row  # sizes: the same for every seed, no "± 0.00" to show
    assert "Timed on a busy machine (busy: load 3.9 on 2 CPUs)" in md
    assert "latency_ms_p10" in report.csv_text(table, report.columns_for([trial(1, 0)])).splitlines()[0]


def label_boxes(fig):
    """(axes box, label text boxes) as drawn, after the layout save_figure applies."""
    fig.tight_layout()
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    return ax.get_window_extent(renderer), [t.get_window_extent(renderer) for t in ax.texts]


def assert_inside_and_apart(frame, boxes):
    assert boxes
    for b in boxes:
        assert frame.x0 <= b.x0 and b.x1 <= frame.x1 and frame.y0 <= b.y0 and b.y1 <= frame.y1, (b, frame)
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b), (a, b)


def test_the_plot_draws_error_bars_and_keeps_labels_inside_and_apart():
    import matplotlib.pyplot as plt

    table = sweep_table()
    sig = {"statistic": "Car mAP", "ci95": {r["label"]: [r["car_mAP"] - 1.5, r["car_mAP"] + 1.2] for r in table}}
    fig = report.figure(table, "latency_ms", "blocks", ("car_mAP", "Car mAP"), sig)
    ax = fig.axes[0]
    bars = [c for c in ax.containers if c.has_yerr and c.has_xerr]
    assert sum(len(c.lines[0].get_xdata()) for c in bars) == 6  # every candidate: mAP interval and latency p10-p90
    assert "bootstrap 95 % interval" in ax.get_title() and "busy machine" in ax.get_title()
    assert sorted(t.get_text() for t in ax.texts) == [f"stage2_blocks={b}" for b in range(1, 7)]
    assert_inside_and_apart(*label_boxes(fig))
    plt.close(fig)


def test_one_candidate_draws_no_front_line():
    import matplotlib.pyplot as plt

    fig = report.figure(sweep_table()[:1], "gflops", "one", ("car_mAP", "Car mAP"))
    ax = fig.axes[0]
    assert [line for line in ax.get_lines() if line.get_label() == "Pareto front"] == []
    assert "Pareto front" not in [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)


def test_nas_pareto_labels_stay_inside_the_axes():
    """Reference models at the plot's right and left edges (yolov8n sits at the largest params)."""
    import matplotlib.pyplot as plt

    records = [{"costs": {"params": p * 1e6}, "mAP50": 40 + 8 * p} for p in (1.0, 1.5, 2.0, 2.5, 3.0)]
    refs = [{"label": "yolov8n", "params": 3.15e6, "mAP50": 64.0},
            {"label": "yolov8n_adapter (inherited)", "params": 3.2e6, "mAP50": 63.5},
            {"label": "yolov8n_small_reference", "params": 0.95e6, "mAP50": 39.0}]
    fig = nas_report.pareto_figure(records, "params", "mAP50", "t", refs)
    assert_inside_and_apart(*label_boxes(fig))
    plt.close(fig)
    fig = nas_report.pareto_figure(records[:1], "params", "mAP50", "t", [])
    assert [line.get_label() for line in fig.axes[0].get_lines()] == ["best subnet (no front)"]
    plt.close(fig)

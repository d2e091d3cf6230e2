"""A range-Doppler sample as a figure that explains itself: the map over radial velocity (m/s,
negative = approaching) and range (m, near at the bottom, as radar displays show it), a colorbar of
the power in the sample's scale, ground-truth boxes solid and detections dashed with class and
score (core/figure.py), a legend. What `dsfec predict --png-dir` writes for RD models; preview.py
keeps the plain pixel picture (two panels, no axes) for data inspection.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...boxes.boxes2d import Boxes2D
from ...core import atomic, figure
from .colormaps import colormap_table
from .sample import RDSample

SCALE_LABELS = {"log10": "power, log10(|X|² + 1)", "db": "power (dB)", "normalised": "normalised power"}


def edge_values(axis: np.ndarray, edges) -> np.ndarray:
    """Cell edges (pixel units: cell k spans [k, k + 1)) -> the axis' physical value there; cell k's
    centre holds axis[k], the axis is uniform."""
    axis = np.asarray(axis, np.float64)
    step = axis[1] - axis[0]
    return axis[0] + (np.asarray(edges, np.float64) - 0.5) * step


def _rectangles(ax, sample: RDSample, boxes: Boxes2D, colors: dict, style: dict, scores=None, labels=None) -> None:
    from matplotlib.patches import Rectangle

    r, v = sample.axes.range_m, sample.axes.velocity_mps
    labelled = figure.labelled(scores) if scores is not None else np.zeros(len(boxes), bool)
    for k, (xyxy, name) in enumerate(zip(boxes.xyxy, boxes.names)):
        v0, v1 = sorted(edge_values(v, xyxy[[0, 2]]))
        r0, r1 = sorted(edge_values(r, xyxy[[1, 3]]))
        color = colors[str(name)]
        ax.add_patch(Rectangle((v0, r0), v1 - v0, r1 - r0, fill=False, edgecolor=color, **style))
        if labelled[k]:
            labels.add(v0, r1, str(name), color, scores[k])


def render_rd_figure(sample: RDSample, predicted: Boxes2D | None = None, classes=(), colormap: str = "viridis",
                     title: str | None = None) -> bytes:
    """PNG bytes of the figure; `classes` fixes the class colours' order (the model's)."""
    from matplotlib.colors import ListedColormap

    predicted = Boxes2D.empty(with_scores=True) if predicted is None else predicted
    colors = figure.class_colors([*classes, *sample.boxes.names, *predicted.names])
    r, v = sample.axes.range_m, sample.axes.velocity_mps
    extent = [*edge_values(v, [0, len(v)]), *edge_values(r, [0, len(r)])]
    fig = figure.new_figure(7.0, 7.5)
    ax = fig.subplots()
    power = np.asarray(sample.power, np.float32)
    if not sample.axes.range_ascending:  # rows far -> near: flip so row 0 is the nearest
        power, extent[2:] = power[::-1], extent[2:][::-1]
    image = ax.imshow(power, origin="lower", extent=extent, aspect="auto", interpolation="nearest",
                      cmap=ListedColormap(colormap_table(colormap) / 255.0))
    fig.colorbar(image, ax=ax, label=SCALE_LABELS.get(sample.scale, sample.scale), fraction=0.05, pad=0.02)
    labels = figure.Labels(ax)
    _rectangles(ax, sample, sample.boxes, colors, figure.GROUND_TRUTH_STYLE)
    _rectangles(ax, sample, predicted, colors, figure.DETECTION_STYLE, predicted.scores, labels)
    ax.axvline(0.0, color="white", lw=0.6, alpha=0.5)  # zero Doppler: static returns
    ax.set_xlabel("radial velocity (m/s), negative = approaching")
    ax.set_ylabel("range (m)")
    return figure.finished(fig, ax, labels, colors, title or sample.sample_id, sample.boxes.names, predicted.names)


def save_rd_figure(sample: RDSample, path, predicted: Boxes2D | None = None, classes=(), colormap: str = "viridis",
                   title: str | None = None) -> Path:
    path = Path(path)
    atomic.write_bytes(path, render_rd_figure(sample, predicted, classes, colormap, title))
    return path

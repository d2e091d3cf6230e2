"""A camera image as a figure that explains itself: the photo at its own pixel size with pixel axes,
ground-truth boxes solid (difficult ones thinner) and detections dashed with class and score
(core/figure.py), a legend. What `dsfec predict --png-dir` writes for camera models; preview.py
keeps the plain picture (boxes burnt into the pixels) for data inspection.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...boxes.boxes2d import Boxes2D
from ...core import atomic, figure
from .images import CameraImage

DPI = 100
MIN_WIDTH_IN = 6.0  # small images are scaled up so labels and legend stay readable


def _rectangles(ax, boxes: Boxes2D, colors: dict, style: dict, scores=None, thin=None, labels=None) -> None:
    from matplotlib.patches import Rectangle

    labelled = figure.labelled(scores) if scores is not None else np.zeros(len(boxes), bool)
    for k, ((x1, y1, x2, y2), name) in enumerate(zip(boxes.xyxy, boxes.names)):
        color = colors[str(name)]
        width = style["linewidth"] * (0.5 if thin is not None and thin[k] else 1.0)
        ax.add_patch(Rectangle((x1, y1), x2 - x1, y2 - y1, fill=False, edgecolor=color,
                               **{**style, "linewidth": width}))
        if labelled[k]:
            labels.add(x1, y1, str(name), color, scores[k])


def render_camera_figure(item: CameraImage, predicted: Boxes2D | None = None, classes=(),
                         title: str | None = None) -> bytes:
    predicted = Boxes2D.empty(with_scores=True) if predicted is None else predicted
    colors = figure.class_colors([*classes, *item.boxes.names, *predicted.names])
    h, w = item.hw
    scale = max(1.0, MIN_WIDTH_IN * DPI / w)
    fig = figure.new_figure(w * scale / DPI + 1.0, h * scale / DPI + 0.9, DPI)
    ax = fig.subplots()
    ax.imshow(item.image, interpolation="nearest")
    labels = figure.Labels(ax)
    _rectangles(ax, item.boxes, colors, figure.GROUND_TRUTH_STYLE, thin=item.difficult)
    _rectangles(ax, predicted, colors, figure.DETECTION_STYLE, predicted.scores, labels=labels)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_xlabel("x (pixels)")
    ax.set_ylabel("y (pixels)")
    ax.tick_params(labelsize=7)
    return figure.finished(fig, ax, labels, colors, title or item.image_id, item.boxes.names, predicted.names)


def save_camera_figure(item: CameraImage, path, predicted: Boxes2D | None = None, classes=(),
                       title: str | None = None) -> Path:
    path = Path(path)
    atomic.write_bytes(path, render_camera_figure(item, predicted, classes, title))
    return path

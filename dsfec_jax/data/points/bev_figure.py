"""A radar frame from above as a figure that explains itself: x forward (up) and y left (to the
left) in metres over the model's grid, range rings every 20 m, the points coloured by their speed
with a colorbar, ground-truth boxes solid and detections dashed with class and score
(core/figure.py), a heading tick on every box, a legend. What `dsfec predict --png-dir` writes for
point models; synthetic/bev_png.py keeps the plain pixel picture for data inspection.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...boxes.geometry import bev_corners
from ...boxes.structures import Boxes
from ...core import atomic, figure
from ...core.grid import Grid
from .frame import Frame

MAX_SPEED = 10.0  # m/s at the top of the colour scale (faster points take its end colour)
# points run from slate (still) to white (fast): no hue, so they never read as a class colour
POINT_COLORS = ("#8090a8", "#f4f8ff")


def point_speed(frame: Frame) -> tuple[np.ndarray, str]:
    """(|speed| per point in m/s, what it is) from whichever velocity columns the frame has."""
    names = frame.point_features
    if "vx_comp" in names:
        return np.hypot(frame.column("vx_comp"), frame.column("vy_comp")), "|compensated velocity| (m/s)"
    for column, what in (("v_r_comp", "|compensated radial speed| (m/s)"), ("v_r", "|radial speed| (m/s)")):
        if column in names:
            return np.abs(frame.column(column)), what
    return np.zeros(len(frame.points)), "no velocity column"


def _outlines(ax, boxes: Boxes, colors: dict, style: dict, scores=None, labels=None) -> None:
    if len(boxes) == 0:
        return
    corners = bev_corners(boxes.center[:, :2], boxes.size[:, :2], boxes.yaw)  # (M, 4, 2) x, y
    labelled = figure.labelled(scores) if scores is not None else np.zeros(len(boxes), bool)
    for k, (c, name) in enumerate(zip(corners, boxes.names)):
        color = colors[str(name)]
        ring = np.vstack([c, c[:1]])
        ax.plot(ring[:, 1], ring[:, 0], color=color, **style)  # horizontal: y, vertical: x
        front = (c[0] + c[3]) / 2
        ax.plot([boxes.center[k, 1], front[1]], [boxes.center[k, 0], front[0]], color=color, lw=1.0)
        if labelled[k]:  # at the box's top-left corner as drawn (y runs right to left)
            labels.add(c[:, 1].max(), c[:, 0].max(), str(name), color, scores[k])


def render_bev_figure(frame: Frame, grid: Grid, predicted: Boxes | None = None, scores=None, classes=(),
                      title: str | None = None) -> bytes:
    """PNG bytes; `predicted` boxes with their `scores`; `classes` fixes the colours' order."""
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    predicted = Boxes.empty() if predicted is None else predicted
    scores = np.zeros(0, np.float32) if scores is None else np.asarray(scores)
    colors = figure.class_colors([*classes, *frame.boxes.names, *predicted.names])
    fig = figure.new_figure(8.0, 8.0)
    ax = fig.subplots()
    ax.set_facecolor("#15151c")
    a = np.linspace(-np.pi, np.pi, 361)
    for r in range(20, int(np.hypot(max(map(abs, grid.x_range)), max(map(abs, grid.y_range)))) + 1, 20):
        ax.plot(r * np.sin(a), r * np.cos(a), color="0.35", lw=0.6, zorder=0)
        ax.text(0.0, r, f"{r} m", color="0.6", fontsize=7, ha="center", va="bottom", clip_on=True)
    speed, what = point_speed(frame)
    dots = ax.scatter(frame.points[:, 1], frame.points[:, 0], c=speed, s=6, cmap=LinearSegmentedColormap.from_list("speed", POINT_COLORS),
                      norm=Normalize(0.0, MAX_SPEED), zorder=2, linewidths=0)
    fig.colorbar(dots, ax=ax, label=f"point speed: {what}", fraction=0.046, pad=0.02, extend="max")
    labels = figure.Labels(ax)
    _outlines(ax, frame.boxes, colors, figure.GROUND_TRUTH_STYLE)
    _outlines(ax, predicted, colors, figure.DETECTION_STYLE, scores, labels)
    ax.set_xlim(grid.y_range[1], grid.y_range[0])  # +y is left: the axis runs right to left
    ax.set_ylim(*grid.x_range)
    ax.set_aspect("equal")
    ax.set_xlabel("y (m), left of the sensor")
    ax.set_ylabel("x (m), ahead of the sensor")
    return figure.finished(fig, ax, labels, colors, title or frame.frame_id, frame.boxes.names, predicted.names)


def save_bev_figure(frame: Frame, path, grid: Grid, predicted: Boxes | None = None, scores=None, classes=(),
                    title: str | None = None) -> Path:
    path = Path(path)
    atomic.write_bytes(path, render_bev_figure(frame, grid, predicted, scores, classes, title))
    return path

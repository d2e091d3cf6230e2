"""What the detection pictures share (BEV, range-Doppler, camera; data/*/figure.py draw them): one
colour per class, ground truth drawn solid and detections dashed with their class and score, a
legend that says which is which, and the figure written as PNG bytes.

matplotlib is imported inside the functions (never at import: the commands that draw nothing stay
light), through `Figure` without pyplot, so no global backend or figure state is shared; savefig
renders with Agg.
"""

from __future__ import annotations

import io
from typing import Iterable, Sequence

import numpy as np

GROUND_TRUTH_STYLE = {"linestyle": "-", "linewidth": 1.6}
DETECTION_STYLE = {"linestyle": (0, (4, 2)), "linewidth": 1.6}
MAX_LABELS = 20  # the best detections of a picture carry a "class score" label; more would cover it


def new_figure(width_in: float, height_in: float, dpi: int = 100):
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), dpi=dpi)


def png_of(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


# bright, saturated class colours: they must stand out on a dark viridis map, a grey BEV and a photo
PALETTE = ("#ff1744", "#ff9100", "#f500f5", "#00e5ff", "#ffea00", "#76ff03", "#2979ff", "#ffffff")


def class_colors(classes: Iterable[str]) -> dict[str, str]:
    """A PALETTE colour per class, in the order given (the model's classes first keep theirs stable)."""
    return {name: PALETTE[k % len(PALETTE)] for k, name in enumerate(dict.fromkeys(str(c) for c in classes))}


def labelled(scores: np.ndarray) -> np.ndarray:
    """Whether each detection gets a text label: the MAX_LABELS best."""
    keep = np.zeros(len(scores), bool)
    keep[np.argsort(-np.asarray(scores), kind="stable")[:MAX_LABELS]] = True
    return keep


def legend(ax, colors: dict, shown: Sequence[str], ground_truth: bool, detections: bool) -> None:
    """Class colours of the `shown` classes, then what solid and dashed outlines mean."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=colors[c], edgecolor=colors[c], label=c) for c in colors if c in set(shown)]
    if ground_truth:
        handles.append(Line2D([], [], color="0.3", label="ground truth", **GROUND_TRUTH_STYLE))
    if detections:
        handles.append(Line2D([], [], color="0.3", label="detection (class score)", **DETECTION_STYLE))
    if handles:
        ax.legend(handles=handles, fontsize=8, framealpha=0.85, loc="best")  # where it covers fewest boxes


LABEL_FONT = 7
TITLE_CHARACTERS = 80  # a longer title (a long file name) wraps rather than running off the figure


def title(ax, text: str) -> None:
    import textwrap

    ax.set_title("\n".join(textwrap.wrap(text, TITLE_CHARACTERS, break_long_words=True)), fontsize=9)


class Labels:
    """Box labels placed once the axes' limits are final: a label that would cover one already
    placed (best scores first) moves up by a line until it is clear (at most MAX_SHIFTS lines)."""

    MAX_SHIFTS = 6

    def __init__(self, ax):
        self.ax, self.wanted = ax, []

    def add(self, x: float, y: float, name: str, color, score: float) -> None:
        """A detection's "class score" label anchored at (x, y), data units (its box's top-left)."""
        text = f"{name} {score:.2f}" if score >= 0.01 else f"{name} {score:.3f}"  # 0.001, not 0.00
        self.wanted.append((-score, len(self.wanted), x, y, text, color))

    def draw(self) -> None:
        ax = self.ax
        ax.apply_aspect()  # an equal-aspect axes settles its box only now
        to_display, to_data = ax.transData, ax.transData.inverted()
        line = LABEL_FONT * 1.6 * ax.figure.dpi / 72  # a label's height in display pixels
        placed: list[tuple[float, float, float, float]] = []
        for _, _, x, y, text, color in sorted(self.wanted):
            px, py = to_display.transform((x, y))
            width = 0.62 * LABEL_FONT * len(text) * ax.figure.dpi / 72
            frame = ax.bbox  # kept inside the axes: a label past an edge would be clipped
            px = max(frame.x0, min(px, frame.x1 - width))
            py = min(py, frame.y1 - line)
            for _ in range(self.MAX_SHIFTS):
                if not any(px < b[2] and b[0] < px + width and py < b[3] and b[1] < py + line for b in placed):
                    break
                py += line
            placed.append((px, py, px + width, py + line))
            tx, ty = to_data.transform((px, py))
            ax.text(tx, ty, text, fontsize=LABEL_FONT, color="white", clip_on=True, ha="left", va="bottom",
                    bbox={"facecolor": "black", "edgecolor": color, "pad": 1.0, "alpha": 0.75})


def finished(fig, ax, labels: Labels, colors: dict, title_text: str, truth, predicted) -> bytes:
    """Title, legend (the classes of `truth` and `predicted` names), layout, then the labels (placed
    in display pixels, so after the layout) -> PNG bytes."""
    title(ax, title_text)
    legend(ax, colors, [*truth, *predicted], len(truth) > 0, len(predicted) > 0)
    fig.tight_layout()
    labels.draw()
    return png_of(fig)

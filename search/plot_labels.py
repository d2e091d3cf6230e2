"""Point labels that stay inside the axes and off each other, for the search plots.

A fixed offset (the reports' old `xytext=(3, 3)`) overlaps labels wherever candidates sit close
(the stage-2 blocks sweep's six candidates) and runs off the axes beside the points at
the edge (the NAS Pareto plots' reference models). `place` tries, for each point, a ring of
offsets around it and keeps the first whose text box lies inside the axes and clear of every
marker, earlier label and the legend, measured in display pixels by the figure's renderer; where
no offset is clear it keeps the inside one that overlaps least. Call it after the figure's layout
is final (`fig.tight_layout()`): it measures where things are drawn.
"""

from __future__ import annotations

# (dx, dy) in points, nearest first; alignment follows the direction so the text grows away from the point
_DIRECTIONS = ((1, 1), (1, -1), (-1, 1), (-1, -1), (0, 1), (0, -1), (1, 0), (-1, 0))
_RADII = (4, 10, 18, 28)
MARKER_PX = 6  # half the side of the box kept clear around each labelled point


def _offsets():
    for r in _RADII:
        for dx, dy in _DIRECTIONS:
            ha = {1: "left", -1: "right", 0: "center"}[dx]
            va = {1: "bottom", -1: "top", 0: "center"}[dy]
            yield dx * r, dy * r, ha, va


def _area(a, b) -> float:
    """Overlap area (px^2) of two display boxes."""
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return max(w, 0.0) * max(h, 0.0)


def _inside(box, frame) -> bool:
    return box.x0 >= frame.x0 and box.x1 <= frame.x1 and box.y0 >= frame.y0 and box.y1 <= frame.y1


def place(ax, points: list[tuple[float, float, str]], fontsize: float = 7, obstacles=()) -> list:
    """Annotate each (x, y, text) of `points` on `ax` -> the annotations. `obstacles`: more
    display boxes to keep clear (matplotlib Bbox)."""
    from matplotlib.transforms import Bbox

    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    taken = list(obstacles)
    legend = ax.get_legend()
    if legend is not None:
        taken.append(legend.get_window_extent(renderer))
    for x, y in ax.transData.transform([(x, y) for x, y, _ in points]) if points else []:
        taken.append(Bbox.from_extents(x - MARKER_PX, y - MARKER_PX, x + MARKER_PX, y + MARKER_PX))
    out = []
    for x, y, text in points:
        best = None  # (outside?, overlap px^2, annotation)
        for dx, dy, ha, va in _offsets():
            # a pale box: a label that must cross an error bar or a front line stays readable
            ann = ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points", ha=ha, va=va,
                              fontsize=fontsize, annotation_clip=False, zorder=5,
                              bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
            box = ann.get_window_extent(renderer)
            score = (not _inside(box, frame), sum(_area(box, t) for t in taken))
            if best is None or score < best[:2]:
                if best is not None:
                    best[2].remove()
                best = (*score, ann, box)
            else:
                ann.remove()
            if score == (False, 0.0):
                break
        taken.append(best[3])
        out.append(best[2])
    return out


def boxes(annotations, renderer) -> list:
    """The display boxes of `annotations` (what the tests compare with the axes' box)."""
    return [a.get_window_extent(renderer) for a in annotations]

"""A top-view map of a drive as PNG, like the paper's Fig. 8(d): the ego track and the placed
objects in a local East-North frame (metres, equal aspect, north up), drawn offline (matplotlib's
Agg renderer through a bare Figure, no map tiles: nothing outside this machine can be reached).

Drawn: the ego track as a line with a marker at its start, every placed object as a filled marker
coloured by class, ground-truth objects (optional) as hollow markers in the same colours, a scale
bar and a legend. The frame's origin is the first ego position unless one is given; positions
come from the frame batches' WGS84 coordinates through geodesy.py. The image is exactly
`size_px` (no tight bounding box, so its size does not depend on the labels).
"""

from __future__ import annotations

import io
import math

import numpy as np

from ..core import atomic
from .geodesy import geodetic_to_enu


def _enu(points: list[tuple[float, float, float]], origin) -> np.ndarray:
    if not points:
        return np.zeros((0, 3))
    lat, lon, alt = np.array(points, np.float64).T
    return geodetic_to_enu(lat, lon, alt, origin)


def _nice_length(span_m: float) -> float:
    """A 1, 2 or 5 x 10^k length near a fifth of the span: the scale bar's."""
    target = max(span_m / 5.0, 1e-3)
    power = 10.0 ** math.floor(math.log10(target))
    return max((m * power for m in (1, 2, 5, 10) if m * power <= target), default=power)


def _class_colors(names) -> dict:
    import matplotlib
    cmap = matplotlib.colormaps["tab10"]
    return {name: cmap(k % 10) for k, name in enumerate(sorted(set(names)))}


def draw_map(batches: list[dict], path=None, *, origin=None, truth: list[dict] | None = None,
             size_px: tuple[int, int] = (900, 900), title: str | None = None) -> bytes:
    """PNG bytes of the map (written atomically to `path` when given). batches: frame batches
    (exchange format); truth: dicts with class, lat, lon (alt optional)."""
    from matplotlib.figure import Figure  # no pyplot: no global backend or figure state to share
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    batches = sorted(batches, key=lambda b: float(b["time"]))
    ego = [(b["ego"]["lat"], b["ego"]["lon"], b["ego"]["alt"]) for b in batches]
    if origin is None:
        if not ego:
            raise ValueError("draw_map needs at least one frame batch, or an origin")
        origin = ego[0]
    objects = [o for b in batches for o in b["objects"]]
    truth = list(truth or [])
    colors = _class_colors([o["class"] for o in objects + truth])
    track = _enu(ego, origin)
    placed = _enu([(o["lat"], o["lon"], o["alt"]) for o in objects], origin)
    true = _enu([(o["lat"], o["lon"], o.get("alt", 0.0)) for o in truth], origin)

    fig = Figure(figsize=(size_px[0] / 100, size_px[1] / 100), dpi=100)
    ax = fig.subplots()
    if len(track):
        devices = [b["device"] for b in batches]
        for k, device in enumerate(dict.fromkeys(devices)):
            rows = [i for i, d in enumerate(devices) if d == device]
            ax.plot(track[rows, 0], track[rows, 1], "-", color="0.2", lw=1.5, label="ego track" if k == 0 else None)
            ax.plot(track[rows[0], 0], track[rows[0], 1], "o", color="0.2", ms=8, mfc="white", mew=2,
                    label="start" if k == 0 else None)
    for name, color in colors.items():
        sel = [k for k, o in enumerate(objects) if o["class"] == name]
        if sel:
            ax.scatter(placed[sel, 0], placed[sel, 1], s=14, color=color, label=name, zorder=3)
        sel = [k for k, o in enumerate(truth) if o["class"] == name]
        if sel:
            ax.scatter(true[sel, 0], true[sel, 1], s=40, facecolors="none", edgecolors=[color], lw=1.0,
                       label=f"{name} (truth)", zorder=2)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.grid(True, lw=0.3, color="0.85")
    ax.set_title(title or f"{len(objects)} placed objects, {len(batches)} frames")
    ax.legend(loc="upper left", fontsize=7, framealpha=0.85)
    fig.tight_layout()
    ax.apply_aspect()
    x0, x1 = ax.get_xlim()
    length = _nice_length(x1 - x0)
    label = f"{length:g} m" if length < 1000 else f"{length / 1000:g} km"
    ax.add_artist(AnchoredSizeBar(ax.transData, length, label, "lower right", pad=0.5, frameon=True, size_vertical=0))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    data = buf.getvalue()
    if path is not None:
        atomic.write_bytes(path, data)
    return data

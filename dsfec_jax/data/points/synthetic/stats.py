"""Dataset statistics for any frames (synthetic or real), and the generator's throughput.

Works on every Frame: per-box point counts come from meta["num_points"] when the source knows
them, else from a point-in-box test; clutter is meta["point_source"] != object when known, else
the points inside no box.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

from ....boxes.geometry import points_in_boxes
from ..frame import Frame
from .config import CLASSES, SOURCES, SyntheticConfig

RANGE_BINS = (0.0, 20.0, 40.0, 60.0, 80.0)
BIN_NAMES = ("0-20", "20-40", "40-60", "60-80", "80+")  # the grid's far corners reach 89 m


def box_point_counts(frame: Frame) -> np.ndarray:
    if "num_points" in frame.meta:
        return np.asarray(frame.meta["num_points"])
    b = frame.boxes
    if len(b) == 0:
        return np.zeros(0, int)
    return points_in_boxes(frame.points[:, :3], b.center, b.size, b.yaw).sum(0)


def clutter_mask(frame: Frame) -> np.ndarray:
    if "point_source" in frame.meta:
        return np.asarray(frame.meta["point_source"]) != 0
    b = frame.boxes
    if len(b) == 0:
        return np.ones(len(frame.points), bool)
    return ~points_in_boxes(frame.points[:, :3], b.center, b.size, b.yaw).any(1)


def dataset_stats(frames: Iterable[Frame], classes=CLASSES) -> dict:
    n_points, n_clutter, sources, names, ranges, counts = [], [], np.zeros(len(SOURCES), int), [], [], []
    for f in frames:
        n_points.append(len(f.points))
        n_clutter.append(int(clutter_mask(f).sum()))
        if "point_source" in f.meta:
            sources += np.bincount(f.meta["point_source"], minlength=len(SOURCES))[:len(SOURCES)]
        names.append(f.boxes.names)
        ranges.append(np.hypot(f.boxes.center[:, 0], f.boxes.center[:, 1]))
        counts.append(box_point_counts(f))
    if not n_points:
        raise ValueError("dataset_stats: no frames")
    n_points = np.array(n_points)
    names, ranges, counts = np.concatenate(names), np.concatenate(ranges), np.concatenate(counts)
    bins = np.digitize(ranges, RANGE_BINS[1:])
    total = max(int(n_points.sum()), 1)
    return dict(
        frames=len(n_points),
        points_per_frame=dict(mean=float(n_points.mean()), median=float(np.median(n_points)),
                              p10=float(np.percentile(n_points, 10)), p90=float(np.percentile(n_points, 90))),
        clutter_share=float(np.sum(n_clutter) / total),
        source_share={s: float(c / total) for s, c in zip(SOURCES, sources)} if sources.any() else {},
        boxes_per_class={c: int(np.sum(names == c)) for c in classes},
        mean_points_per_box={c: _mean(counts[names == c]) for c in classes},
        share_with_points={c: {b: _share(counts[(names == c) & (bins == i)]) for i, b in enumerate(BIN_NAMES)}
                           for c in classes},
        boxes_per_bin={c: {b: int(np.sum((names == c) & (bins == i))) for i, b in enumerate(BIN_NAMES)}
                       for c in classes},
    )


def _mean(x):
    return float(x.mean()) if len(x) else None


def _share(counts):
    return float(np.mean(counts >= 1)) if len(counts) else None


def format_stats(s: dict) -> str:
    p = s["points_per_frame"]
    lines = [f"frames {s['frames']}  points/frame mean {p['mean']:.1f} median {p['median']:.0f} "
             f"(p10 {p['p10']:.0f}, p90 {p['p90']:.0f})  clutter share {s['clutter_share']:.1%}"]
    if s["source_share"]:
        lines.append("point sources: " + ", ".join(f"{k} {v:.1%}" for k, v in s["source_share"].items()))
    lines.append(f"{'class':<11}{'boxes':>7}{'pts/box':>9}  share with >=1 point by range (m) [boxes]")
    lines.append(" " * 29 + "".join(f"{b:>15}" for b in BIN_NAMES))
    for c, n in s["boxes_per_class"].items():
        mean = s["mean_points_per_box"][c]
        cells = "".join(f"{_fmt(s['share_with_points'][c][b]):>7} [{s['boxes_per_bin'][c][b]:>5}]" for b in BIN_NAMES)
        lines.append(f"{c:<11}{n:>7}{'-' if mean is None else f'{mean:.1f}':>9}  {cells}")
    return "\n".join(lines)


def _fmt(x):
    return "-" if x is None else f"{x:.0%}"


def throughput(cfg: SyntheticConfig | None = None, frames: int = 200, split: str = "train", seed: int = 0) -> float:
    """Frames generated per second in this process (one core: numpy here is single-threaded)."""
    from .dataset import generate_frame

    cfg = cfg or SyntheticConfig()
    generate_frame(cfg, split, 0, seed)  # warm caches and lazy imports
    start = time.perf_counter()
    for i in range(frames):
        generate_frame(cfg, split, i, seed)
    return frames / (time.perf_counter() - start)

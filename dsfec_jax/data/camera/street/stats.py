"""Statistics of street frames: objects per frame by class, the difficult share, dropped objects,
box sizes in pixels, visible fractions, the depth range, and the generation rate."""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

from .config import CLASSES
from .frame import StreetFrame
from .labels import DROP_REASONS


def summary(x, digits: int = 3) -> dict | None:
    """median, p10, p90, min, max and count of the finite values of x (None when there are none)."""
    x = np.asarray(x, np.float64).reshape(-1)
    x = x[np.isfinite(x)]
    if not len(x):
        return None
    return {k: round(float(v), digits) for k, v in dict(
        median=np.median(x), p10=np.percentile(x, 10), p90=np.percentile(x, 90), min=x.min(), max=x.max()).items()} \
        | {"count": int(len(x))}


def frame_stats(frames: Iterable[StreetFrame], classes=CLASSES) -> dict:
    counts, names, difficult, heights, widths, visible, obj_depth = [], [], [], [], [], [], []
    dropped = {r: 0 for r in DROP_REASONS}
    depth_lo, depth_hi, sky, shapes = [], [], [], set()
    for f in frames:
        shapes.add(f.image.shape[:2])
        counts.append(len(f.boxes))
        names.append(np.asarray(f.boxes.names))
        difficult.append(np.asarray(f.boxes.difficult, bool))
        wh = f.boxes.wh.reshape(-1, 2)
        widths.append(wh[:, 0])
        heights.append(wh[:, 1])
        visible.append(f.objects.visible_fraction)
        obj_depth.append(f.objects.center_cam[:, 2])
        for r in DROP_REASONS:
            dropped[r] += int(f.meta.get("dropped", {}).get(r, 0))
        finite = np.isfinite(f.depth)
        sky.append(1 - finite.mean())
        if finite.any():
            depth_lo.append(float(f.depth[finite].min()))
            depth_hi.append(float(np.percentile(f.depth[finite], 99)))
    n = len(counts)
    if not n:
        raise ValueError("frame_stats: no frames")
    names, difficult = np.concatenate(names), np.concatenate(difficult)
    heights, widths, obj_depth = np.concatenate(heights), np.concatenate(widths), np.concatenate(obj_depth)
    per_class = {}
    for c in classes:
        sel = names == c
        per_class[c] = dict(per_frame=round(float(sel.sum() / n), 3),
                            difficult_share=round(float(difficult[sel].mean()), 3) if sel.any() else None,
                            box_height_px=summary(heights[sel], 1), box_width_px=summary(widths[sel], 1),
                            depth_m=summary(obj_depth[sel], 1))
    counts = np.asarray(counts)
    return dict(
        frames=n, resolution=[list(s)[::-1] for s in sorted(shapes)],  # [width, height]
        empty_frame_share=round(float(np.mean(counts == 0)), 3),
        objects_per_frame=dict(all=round(float(counts.mean()), 3), **{c: per_class[c]["per_frame"] for c in classes}),
        boxes=int(len(names)),
        difficult_share=round(float(difficult.mean()), 3) if len(difficult) else None,
        dropped_per_frame={r: round(v / n, 3) for r, v in dropped.items()},
        box_height_px=summary(heights, 1), box_width_px=summary(widths, 1),
        visible_fraction=summary(np.concatenate(visible), 3),
        by_class=per_class,
        depth_m=dict(nearest=summary(depth_lo, 2), p99=summary(depth_hi, 1), sky_share=summary(sky, 3)),
    )


def _fmt(s: dict | None, digits: int = 1) -> str:
    if s is None:
        return "-"
    return f"{s['median']:.{digits}f} [{s['p10']:.{digits}f}, {s['p90']:.{digits}f}]"


def format_frame_stats(name: str, s: dict) -> str:
    """A text table: medians with [p10, p90]."""
    rows = [("frames", str(s["frames"])), ("resolution", ", ".join(f"{w}x{h}" for w, h in s["resolution"])),
            ("empty frames", f"{s['empty_frame_share']:.0%}"),
            ("objects / frame", f"{s['objects_per_frame']['all']:.2f}")]
    for c, v in s["by_class"].items():
        share = "-" if v["difficult_share"] is None else f"{v['difficult_share']:.0%}"
        rows.append((f"  {c} / frame (difficult)", f"{v['per_frame']:.2f} ({share})"))
    rows += [("difficult share", "-" if s["difficult_share"] is None else f"{s['difficult_share']:.1%}"),
             ("dropped / frame", ", ".join(f"{k} {v:.2f}" for k, v in s["dropped_per_frame"].items())),
             ("box height px", _fmt(s["box_height_px"])), ("box width px", _fmt(s["box_width_px"])),
             ("visible fraction", _fmt(s["visible_fraction"], 2))]
    for c, v in s["by_class"].items():
        rows.append((f"  {c} height px / depth m", f"{_fmt(v['box_height_px'])} / {_fmt(v['depth_m'])}"))
    d = s["depth_m"]
    rows += [("nearest depth m", _fmt(d["nearest"], 2)), ("p99 depth m", _fmt(d["p99"])),
             ("sky share (depth inf)", _fmt(d["sky_share"], 3))]
    width = max(len(r[0]) for r in rows) + 2
    return "\n".join([name] + [f"{label:<{width}}{value}" for label, value in rows])


def generation_rate(make, count: int) -> float:
    """Frames per second of make(index) over `count` calls in this process, after one warm-up call
    (run under `taskset -c 0` for a per-core figure)."""
    make(0)
    start = time.perf_counter()
    for i in range(count):
        make(i + 1)
    return count / (time.perf_counter() - start)

"""What is in a data source, frame by frame: points, boxes per class, boxes with >= 1 point.

"Boxes with >= 1 point" uses the same rule as the real-sample acceptance counts (boxes grown by
0.2 m in x/y and 0.5 m in z on each side, see kitti.boxes_with_points), for every source.
"""

from __future__ import annotations

import collections
import time
from pathlib import Path
from typing import Iterable

import numpy as np

from ...core.grid import DSFEC_GRID
from .frame import Boxes, Frame
from .kitti import boxes_with_points, list_frames, read_tj4d_frame, read_vod_frame
from .pillarize import PillarSpec, pillarize
from .nuscenes import NUSCENES_FEATURES, drop_nonfinite, radar_features, read_radar_pcd

SOURCES = ("synthetic", "nuscenes-pcd", "vod", "tj4d")
# The DSFEC pillar tensors (8000 pillars x 8 points, 7 features) as the throughput reference.
DSFEC_SPEC = PillarSpec(DSFEC_GRID, NUSCENES_FEATURES, 8000, 8)


def frame_summary(frame: Frame) -> dict:
    hit = boxes_with_points(frame) if len(frame.boxes) else np.zeros(0, bool)
    names = frame.boxes.names
    return {
        "frame": frame.frame_id,
        "points": int(len(frame.points)),
        "boxes": dict(collections.Counter(names.tolist())),
        "boxes_with_points": dict(collections.Counter(names[hit].tolist())),
        "num_boxes": int(len(names)),
        "num_boxes_with_points": int(hit.sum()),
    }


def summarize(frames: Iterable[Frame]) -> dict:
    rows = [frame_summary(f) for f in frames]
    total = {"frames": len(rows), "points": sum(r["points"] for r in rows),
             "num_boxes": sum(r["num_boxes"] for r in rows),
             "num_boxes_with_points": sum(r["num_boxes_with_points"] for r in rows)}
    for key in ("boxes", "boxes_with_points"):
        total[key] = dict(sum((collections.Counter(r[key]) for r in rows), collections.Counter()))
    return {"frames": rows, "total": total}


def pcd_frames(path: Path) -> list[Frame]:
    files = sorted(path.glob("*.pcd")) if path.is_dir() else [path]
    if not files:
        raise FileNotFoundError(f"{path}: no .pcd files")
    frames = []
    for f in files:
        pcd, dropped = drop_nonfinite(read_radar_pcd(f))
        frames.append(Frame(radar_features(pcd), NUSCENES_FEATURES, Boxes.empty(), f.stem, "nuscenes",
                            {"dropped_nonfinite": dropped}))
    return frames


def load(source: str, target: str, split: str = "val", frames: int = 20, seed: int = 0) -> tuple[list[Frame], dict]:
    """Frames of a source, plus facts about how they were obtained (e.g. generation rate)."""
    if source == "synthetic":
        from .synthetic import SyntheticConfig, generate_frame
        cfg = SyntheticConfig()
        t0 = time.perf_counter()
        out = [generate_frame(cfg, split, i, seed) for i in range(frames)]
        return out, {"split": split, "seed": seed, "frames_per_s": round(frames / (time.perf_counter() - t0), 1)}
    path = Path(target)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or directory for source {source!r}")
    if source == "nuscenes-pcd":
        return pcd_frames(path), {}
    if source == "vod":
        return [read_vod_frame(path, i) for i in list_frames(path)], {}
    if source == "tj4d":
        return [read_tj4d_frame(path, i) for i in list_frames(path)], {}
    raise ValueError(f"unknown source {source!r}; valid: {SOURCES}")


def pillarize_rate(frames: list[Frame], spec: PillarSpec) -> dict:
    """Host pillarization throughput over these frames (points/s and frames/s)."""
    arrays = [np.asarray(f.points[:, :len(spec.features)], np.float32) for f in frames]
    t0 = time.perf_counter()
    for a in arrays:
        pillarize(np.pad(a, ((0, 0), (0, len(spec.features) - a.shape[1]))), spec)
    dt = time.perf_counter() - t0
    return {"pillarize_points_per_s": round(sum(len(a) for a in arrays) / dt),
            "pillarize_frames_per_s": round(len(arrays) / dt, 1)}


def format_summary(summary: dict) -> str:
    lines = []
    for r in summary["frames"] + [dict(summary["total"], frame="TOTAL")]:
        lines.append(f"{r['frame']:<40} points {r['points']:>7}  boxes with >= 1 point "
                     f"{r['num_boxes_with_points']}/{r['num_boxes']}  {r['boxes']}")
    for key, value in summary.get("info", {}).items():
        lines.append(f"{key}: {value}")
    return "\n".join(lines)

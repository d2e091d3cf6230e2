"""`python -m dsfec_jax.data inspect --source street`: statistics of generated frames, the rate they
were generated at, and PNG previews (image with boxes | depth | right image) with previews.json
recording what made them (the command, split, seed, config, versions), as every shipped picture must."""

from __future__ import annotations

import time
from pathlib import Path

from ....core.atomic import write_json
from ....core.provenance import versions
from .config import StreetConfig
from .generate import generate_frame
from .preview import CLASS_COLORS, DEPTH_RANGE_M, save_street_png
from .stats import format_frame_stats, frame_stats


def inspect_street(split: str | None = None, count: int = 20, seed: int = 0, png_dir: str | None = None,
                   previews: int = 3, command: str = "", cfg: StreetConfig | None = None) -> dict:
    cfg, split = cfg or StreetConfig(), split or "val"
    start = time.perf_counter()  # the frames inspected are the ones timed: no second pass
    frames = [generate_frame(cfg, split, i, seed) for i in range(count)]
    rate = count / (time.perf_counter() - start)
    info = {"split": split, "seed": seed, "frames_per_s": round(rate, 2), "camera": cfg.camera,
            "intrinsics": cfg.camera_model().describe(), "right_image": cfg.render_right,
            "baseline_m": cfg.baseline_m, "gps_origin": list(cfg.origin)}
    summary = {"source": "street", "stats": frame_stats(frames), "info": info}
    if png_dir:
        files = [save_street_png(f, Path(png_dir) / f"{f.frame_id}.png") for f in frames[:previews]]
        summary["previews"] = [str(f) for f in files]
        write_json(Path(png_dir) / "previews.json", {
            "command": command, "source": "street", "split": split, "seed": seed, "files": [f.name for f in files],
            "panels": "image with boxes (difficult dashed) | depth, viridis log scale | right image",
            "class_colors": CLASS_COLORS, "depth_range_m": list(DEPTH_RANGE_M), "config": cfg.to_dict(),
            "versions": versions(("numpy", "pymap3d", "dsfec_jax"))})
    return summary


def format_street(summary: dict) -> str:
    lines = [format_frame_stats(f"street {summary['info']['split']}", summary["stats"])]
    lines += [f"{key}: {value}" for key, value in summary["info"].items()]
    lines += [f"wrote {p}" for p in summary.get("previews", [])]
    return "\n".join(lines)

"""python -m dsfec_jax.data.camera.street [--split train] [--frames 200] [--seed 0] [--camera paper]
[--width 416] [--no-right] [--bench 20] [--cache DIR] [--png DIR]

Prints the statistics of a split of independent street frames and the generation rate on this
process (run under `taskset -c 0` for one core); optionally writes the frames to a cache
directory (PNG + .npz per frame, then manifest.json) and PNG previews.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from ....argtypes import non_negative_int, positive_int
from .cache import write_cache
from .camera import CAMERAS
from .config import StreetConfig
from .generate import SPLITS, StreetDataset, generate_frame
from .preview import save_street_png
from .stats import format_frame_stats, frame_stats, generation_rate


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.data.camera.street", description=__doc__.splitlines()[0])
    p.add_argument("--split", default="train", choices=SPLITS)
    p.add_argument("--frames", type=positive_int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--camera", default="paper", choices=tuple(CAMERAS))
    p.add_argument("--width", type=positive_int, default=416, help="rendered width (the preset's intrinsics scale)")
    p.add_argument("--no-right", action="store_true", help="skip the right image")
    p.add_argument("--json", action="store_true", help="print the statistics as JSON")
    p.add_argument("--bench", type=non_negative_int, default=20, help="time generating this many frames (0: no)")
    p.add_argument("--cache", default=None, metavar="DIR", help="also write the frames to this cache directory")
    p.add_argument("--png", default=None, metavar="DIR", help="write previews of the first --previews frames")
    p.add_argument("--previews", type=non_negative_int, default=3)
    return p.parse_args(argv)


def main(argv=None) -> None:
    args = parse(argv)
    cfg = dataclasses.replace(StreetConfig(), camera=args.camera, width=args.width, render_right=not args.no_right)
    data = StreetDataset(cfg, args.split, args.seed, args.frames)
    stats = frame_stats(data)
    print(json.dumps(stats, indent=2) if args.json else format_frame_stats(f"street {args.split}", stats))
    if args.bench:
        rate = generation_rate(lambda i: generate_frame(cfg, args.split, i, args.seed), args.bench)
        print(f"generation: {rate:.2f} frames/s at {cfg.camera_model().width}x{cfg.camera_model().height}"
              f"{'' if cfg.render_right else ' (no right image)'} ({args.bench} frames, one process)")
    if args.png:
        for i in range(min(args.previews, len(data))):
            frame = data[i]
            print(f"wrote {save_street_png(frame, f'{args.png}/{frame.frame_id}.png')}")
    if args.cache:
        print(f"wrote {len(data)} frames to {write_cache(data, args.cache)}")


if __name__ == "__main__":
    main()

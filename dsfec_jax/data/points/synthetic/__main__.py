"""python -m dsfec_jax.data.points.synthetic [--profile nuscenes|4d] [--split train] [--frames 500] [--difficulty normal]

Prints the statistics of a synthetic split (and, with --bench N, generation frames/s on this
core); optionally writes one frame's BEV picture and/or the frames to a cache directory.
"""

from __future__ import annotations

import argparse
import json

from ....argtypes import non_negative_int, positive_int
from .bev_png import save_bev_png
from .config import DIFFICULTIES, SyntheticConfig, radar4d_config
from .dataset import SPLITS, SyntheticDataset, write_cache
from .stats import dataset_stats, format_stats, throughput


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.data.points.synthetic", description=__doc__.splitlines()[0])
    p.add_argument("--profile", default="nuscenes", choices=("nuscenes", "4d"),
                   help="nuscenes: the default ARS408-like sensor; 4d: the VoD-like 4D imaging radar")
    p.add_argument("--split", default="train", choices=SPLITS)
    p.add_argument("--frames", type=positive_int, default=500)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--difficulty", default="normal", choices=sorted(DIFFICULTIES))
    p.add_argument("--sweeps", type=positive_int, default=None, help="accumulated sweeps (default: the profile's)")
    p.add_argument("--json", action="store_true", help="print the statistics as JSON")
    p.add_argument("--bench", type=non_negative_int, default=0, help="also time generating this many frames (0: no)")
    p.add_argument("--png", default=None, help="write the BEV picture of frame --png-index here")
    p.add_argument("--png-index", type=non_negative_int, default=0)
    p.add_argument("--cache", default=None, help="also write the frames to this cache directory")
    return p.parse_args(argv)


def main(argv=None) -> None:
    args = parse(argv)
    make = radar4d_config if args.profile == "4d" else SyntheticConfig
    sweeps = {} if args.sweeps is None else {"num_sweeps": args.sweeps}
    cfg = make(difficulty=args.difficulty, **sweeps)
    ds = SyntheticDataset(cfg, args.split, args.seed, args.frames)
    stats = dataset_stats(ds)
    print(json.dumps(stats, indent=2) if args.json else format_stats(stats))
    if args.bench:
        print(f"generation: {throughput(cfg, args.bench, args.split, args.seed):.0f} frames/s "
              f"({args.bench} frames, {cfg.difficulty}, {cfg.num_sweeps} sweeps)")
    if args.png:
        save_bev_png(ds[args.png_index], args.png, cfg.grid)
        print(f"wrote {args.png}")
    if args.cache:
        print(f"wrote {len(ds)} frames to {write_cache(ds, args.cache)}")


if __name__ == "__main__":
    main()

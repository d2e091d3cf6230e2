"""python -m dsfec_jax.data inspect --source synthetic|nuscenes-pcd|vod|tj4d [PATH] [--json]

Per frame and in total: points, boxes per class, boxes with >= 1 point. For synthetic,
--split/--frames/--seed select the frames and the generation rate is printed.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..argtypes import positive_int
from .points.inspect import DSFEC_SPEC, SOURCES, format_summary, load, pillarize_rate, summarize


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.data", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    i = sub.add_parser("inspect", help="summarise the frames of a data source")
    i.add_argument("target", nargs="?", default="", help="a path (real sources) or a split name (synthetic)")
    i.add_argument("--source", required=True, choices=SOURCES)
    i.add_argument("--split", default=None, help="synthetic split: train, val or test (default val)")
    i.add_argument("--frames", type=positive_int, default=20, help="synthetic: number of frames")
    i.add_argument("--seed", type=int, default=0)
    i.add_argument("--json", action="store_true")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse(argv)
    split = args.split or (args.target if args.source == "synthetic" and args.target else "val")
    if args.source != "synthetic" and not args.target:
        sys.exit(f"--source {args.source} needs a PATH")
    try:
        frames, info = load(args.source, args.target, split, args.frames, args.seed)
    except (FileNotFoundError, ValueError) as err:
        sys.exit(str(err))
    summary = summarize(frames)
    summary["info"] = {**info, **pillarize_rate(frames, DSFEC_SPEC)} if frames else info
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

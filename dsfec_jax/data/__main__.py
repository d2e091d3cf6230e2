"""python -m dsfec_jax.data inspect --source SOURCE [PATH] [--json]

Point clouds (synthetic, nuscenes-pcd, vod, tj4d): per frame and in total, points, boxes per
class, boxes with >= 1 point. Range-Doppler maps (rd-synthetic, ti-adc, raddet, carrada): objects
per frame by class, box sizes in bins, the noise floor, target peaks above it, the zero-Doppler
ridge's share of power, the map's structure per channel count (ridge over the row floor, floor
shape, peak; --versus SOURCE[:PATH] adds another source's beside it); the generation rate
(rd-synthetic, --benchmark picks its version) or the strongest moving target (ti-adc); --png DIR
writes previews of both input representations. Street scenes (street, the
camera benchmark): objects per frame by class, difficult share, box sizes, depth range, the
generation rate; --png DIR writes previews (image with boxes | depth | right image). For synthetic
sources --split/--frames/--seed select the frames.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys

from ..argtypes import non_negative_int, positive_int
from .points.inspect import DSFEC_SPEC, SOURCES, format_summary, load, pillarize_rate, summarize
from .rd.colormaps import COLORMAPS
from .rd.inspect import RD_SOURCES, inspect_rd
from .rd.stats import format_stats_table, format_structure_table
from .rd.synthetic.config import BENCHMARK_VERSIONS

STREET = "street"


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.data", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    i = sub.add_parser("inspect", help="summarise the frames of a data source")
    i.add_argument("target", nargs="?", default="", help="a path (real sources) or a split name (synthetic)")
    i.add_argument("--source", required=True, choices=SOURCES + RD_SOURCES + (STREET,))
    i.add_argument("--split", default=None, help="synthetic split: train, val or test (default val); "
                   "raddet/carrada: a split folder / CARRADA split")
    i.add_argument("--frames", type=positive_int, default=20, help="synthetic: number of frames; RD: samples read")
    i.add_argument("--seed", type=int, default=0)
    i.add_argument("--png", default=None, metavar="DIR", help="RD and street sources: write PNG previews here")
    i.add_argument("--previews", type=non_negative_int, default=3, help="RD and street sources: number of previews")
    i.add_argument("--colormap", default="viridis", choices=COLORMAPS, help="RD sources: the heatmap's colormap")
    i.add_argument("--benchmark", type=int, default=None, choices=BENCHMARK_VERSIONS,
                   help="rd-synthetic: the benchmark version (default 2, issue 54's clutter, IF chain and coupling, the shipped RD weights'; 1: before it)")
    i.add_argument("--versus", default=None, metavar="SOURCE[:PATH]",
                   help="RD sources: another source's map structure beside this one's, e.g. ti-adc:DIR")
    i.add_argument("--json", action="store_true")
    return p.parse_args(argv)


def inspect_points(args) -> str:
    split = args.split or (args.target if args.source == "synthetic" and args.target else "val")
    frames, info = load(args.source, args.target, split, args.frames, args.seed)
    summary = summarize(frames)
    summary["info"] = {**info, **pillarize_rate(frames, DSFEC_SPEC)} if frames else info
    return json.dumps(summary, indent=2) if args.json else format_summary(summary)


def inspect_maps(args, argv) -> str:
    split = args.split or (args.target if args.source == "rd-synthetic" and args.target else None)
    target = "" if args.source == "rd-synthetic" else args.target
    command = "python -m dsfec_jax.data " + shlex.join(sys.argv[1:] if argv is None else argv)
    summary = inspect_rd(args.source, target, split, args.frames, args.seed, args.png, args.previews, args.colormap,
                         command, args.benchmark, args.versus)
    if args.json:
        return json.dumps(summary, indent=2)
    lines = [format_stats_table(summary["stats_by_channels"]), "", format_structure_table(summary["structure"]), ""]
    for key, value in summary["info"].items():
        lines.append(f"{key}: {value}")
    lines += [f"wrote {p}" for p in summary.get("previews", [])]
    return "\n".join(lines)


def inspect_street(args, argv) -> str:
    from .camera.street.inspect import format_street, inspect_street as inspect
    command = "python -m dsfec_jax.data " + shlex.join(sys.argv[1:] if argv is None else argv)
    summary = inspect(args.split or args.target or None, args.frames, args.seed, args.png, args.previews, command)
    return json.dumps(summary, indent=2) if args.json else format_street(summary)


def main(argv=None) -> int:
    args = parse(argv)
    if args.source not in ("synthetic", "rd-synthetic", STREET) and not args.target:
        sys.exit(f"--source {args.source} needs a PATH")
    try:
        if args.source == STREET:
            print(inspect_street(args, argv))
        else:
            print(inspect_maps(args, argv) if args.source in RD_SOURCES else inspect_points(args))
    except (FileNotFoundError, ValueError) as err:
        sys.exit(str(err))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

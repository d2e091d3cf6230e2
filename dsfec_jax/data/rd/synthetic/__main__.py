"""python -m dsfec_jax.data.rd.synthetic [--split train] [--samples 500] [--seed 0] [--benchmark 1|2] [--cache DIR] [--png DIR]

Prints the statistics of a synthetic RD split and its generation rate on this core; optionally
writes the samples to a cache directory (.npz files, then manifest.json) and PNG previews.
"""

from __future__ import annotations

import argparse
import json

from ....argtypes import non_negative_int, positive_int
from ..preview import save_rd_png
from ..stats import dataset_stats, format_stats_table, generation_rate
from .config import BENCHMARK_VERSIONS, DEFAULT_BENCHMARK, benchmark_config
from .dataset import SPLITS, RDSyntheticDataset, generate_sample, write_cache


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m dsfec_jax.data.rd.synthetic", description=__doc__.splitlines()[0])
    p.add_argument("--split", default="train", choices=SPLITS)
    p.add_argument("--samples", type=positive_int, default=500)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--benchmark", type=int, default=DEFAULT_BENCHMARK, choices=BENCHMARK_VERSIONS,
                   help="the benchmark version (1: before issue 54's realism, what the shipped RD weights saw)")
    p.add_argument("--json", action="store_true", help="print the statistics as JSON")
    p.add_argument("--bench", type=non_negative_int, default=100, help="time generating this many maps (0: no)")
    p.add_argument("--cache", default=None, metavar="DIR", help="also write the samples to this cache directory")
    p.add_argument("--png", default=None, metavar="DIR", help="write previews of the first --previews samples")
    p.add_argument("--previews", type=non_negative_int, default=3)
    return p.parse_args(argv)


def main(argv=None) -> None:
    args = parse(argv)
    cfg = benchmark_config(args.benchmark)
    data = RDSyntheticDataset(cfg, args.split, args.seed, args.samples)
    stats = dataset_stats(data)
    print(json.dumps(stats, indent=2) if args.json else format_stats_table({f"rd-synthetic {args.split}": stats}))
    if args.bench:
        rate = generation_rate(lambda i: generate_sample(cfg, args.split, i, args.seed), args.bench)
        print(f"generation: {rate:.0f} maps/s ({args.bench} maps, one process)")
    if args.png:
        for i in range(min(args.previews, len(data))):
            sample = data[i]
            print(f"wrote {save_rd_png(sample, f'{args.png}/{sample.sample_id}.png')}")
    if args.cache:
        print(f"wrote {len(data)} samples to {write_cache(data, args.cache)}")


if __name__ == "__main__":
    main()

"""One-shot NAS: python -m search.nas --space yolov8n_adapter [--profile smoke|quick|paper]
    [--strategy evolution|nsga2] [--max-params 2.65e6] [--max-gflops G] [--max-latency-ms MS]
    [--latency-table FILE] [--objective params|gflops|latency_ms]
    [--seed 0] [--sampling uniform|sandwich] [--run-dir runs/nas/SPACE] [--standalone 5] [--spread 3]
    [--spread-by score|params|gflops|latency_ms] [--backend local|ray [--address ADDR] [--workers N]]
    [--register yolov8n_adapter_search] [--record search/nas/records/ranking_SPACE.json]

Trains the space's weight-sharing supernet by SPOS (resumable), searches it under the limits
(the paper's evolution, or Optuna's NSGA-II), and writes RUN_DIR/report.md with the generation
table, the top subnets and Pareto plots (pareto_params.png, pareto_gflops.png). --standalone K
trains the top K subnets from scratch (and --spread N more across the ranking) with the family's
recipe, in RUN_DIR/standalone, and adds the ranking study (Kendall tau, inherited against
stand-alone mAP) to the report and RUN_DIR/ranking.json; --register then takes the best
stand-alone subnet, and --record FILE keeps the study with the run's command, seed and versions
(a record to ship beside docs/search.md's figures: RUN_DIR is scratch). --backend ray scores each generation's subnets on N Ray actors (the supernet
still trains here first) and runs the stand-alone trainings as Ray Tune trials. Run the same
command again to resume a killed run.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import shlex
import sys

from dsfec_jax.argtypes import positive_int
from dsfec_jax.core import progress
from dsfec_jax.train import parallel

from .run import PROFILES, run_nas
from .spaces import SPACES
from .spos import SAMPLINGS


def parse(argv: list[str]) -> argparse.Namespace:
    """The command's arguments, checked (argument errors exit here, before anything trains)."""
    p = argparse.ArgumentParser(prog="python -m search.nas", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--space", required=True, choices=sorted(SPACES))
    p.add_argument("--profile", default="quick", choices=sorted(PROFILES))
    p.add_argument("--strategy", default="evolution", choices=("evolution", "nsga2"))
    p.add_argument("--max-params", type=float, default=None, help="limit on BN-folded parameters (the paper's subnet: 2.65e6)")
    p.add_argument("--max-gflops", type=float, default=None, help="limit on GFLOPs (2 x MACs at 256 x 64)")
    p.add_argument("--max-latency-ms", type=float, default=None,
                   help="limit on the latency table's prediction (python -m search.nas.latency builds the table)")
    p.add_argument("--latency-table", default=None, help="default search/nas/records/latency_SPACE.json")
    p.add_argument("--objective", default="params", choices=("params", "gflops", "latency_ms"),
                   help="NSGA-II's cost objective")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sampling", default="uniform", choices=SAMPLINGS,
                   help="SPOS's subnet per batch: uniform, or the sandwich rule (largest, smallest, 2 uniform, "
                        "accumulated into one update; DSFEC-style spaces); kept in RUN_DIR/supernet/run.json")
    p.add_argument("--run-dir", default=None)
    p.add_argument("--devices", type=positive_int, default=None,
                   help="local devices the supernet trains on, its batch split across them (default: all; on "
                        "the CPU, N > 1 makes N host devices): dsfec_jax.train.parallel")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--register", default=None, metavar="NAME",
                   help="register the best subnet as zoo model NAME (e.g. yolov8n_adapter_search: models/yolo_rd/searched.json)")
    p.add_argument("--record", default=None, metavar="FILE",
                   help="with --standalone/--spread: also write the ranking study with the run's command, seed and "
                        "environment to FILE (e.g. search/nas/records/ranking_SPACE.json, to ship)")
    p.add_argument("--standalone", type=int, default=0, metavar="K",
                   help="train the top K subnets stand-alone (the family's recipe of this profile)")
    p.add_argument("--spread", type=int, default=0, metavar="N",
                   help="and N more spaced across the inherited ranking, for the ranking study")
    p.add_argument("--spread-by", default="score", choices=("score", "params", "gflops", "latency_ms"),
                   help="space the --spread subnets over the inherited ranking or over a cost's range")
    p.add_argument("--backend", default="local", choices=("local", "ray"),
                   help="score subnets and train the stand-alone ones here, or on Ray (scoring actors, Tune trials)")
    p.add_argument("--address", default=None, help="with --backend ray: an existing cluster")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="with --backend ray: scoring actors, 1 CPU each (default: the cluster's CPUs, "
                        "at most the population)")
    args = p.parse_args(argv)
    if args.standalone < 0 or args.spread < 0:
        p.error("--standalone and --spread take counts >= 0")
    if args.record and not (args.standalone or args.spread):
        p.error("--record keeps the ranking study: it goes with --standalone K or --spread N")
    if args.workers is not None and (args.backend != "ray" or args.workers < 1):
        p.error("--workers N (N >= 1) goes with --backend ray")
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse(argv)
    limits = {k: v for k, v in (("params", args.max_params), ("gflops", args.max_gflops),
                                ("latency_ms", args.max_latency_ms)) if v is not None}
    run_dir = args.run_dir or f"runs/nas/{args.space}_{args.profile}_{args.strategy}"
    parallel.start_or_exit(args, "python -m search.nas")  # before anything runs JAX
    with progress.watched("search.nas", enabled=not args.no_progress):
        report = run_nas(args.space, run_dir, args.profile, args.strategy, limits, args.seed, args.objective,
                         command=shlex.join(["python", "-m", "search.nas", *argv]), progress=not args.no_progress,
                         register_as=args.register, latency_path=args.latency_table, standalone=args.standalone,
                         spread=args.spread, spread_by=args.spread_by, backend=args.backend, address=args.address,
                         workers=args.workers, sampling=args.sampling, record_path=args.record)
    print(f"report: {report}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

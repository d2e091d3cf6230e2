"""Flags and the run shared by the search entry points (blocks, stem, activations, grid)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from dsfec_jax.core import atomic, progress

from .recipes import PROFILES, get_recipe
from .report import write_reports
from .oneshot import hooks, run_oneshot, supernet_overrides
from .runners import run_local, run_ray
from .space import SearchSpaceError
from .trial import make_trial


def parser(prog: str, doc: str, base: str = "dsfec_l", strategy: str = "train") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=doc.strip().splitlines()[0])
    p.add_argument("--base", default=base, help="registered model the candidates override")
    p.add_argument("--profile", default="quick", choices=PROFILES, help="training recipe per trial")
    p.add_argument("--data", default=None, help="synthetic | synthetic4d | vod:PATH | tj4d:PATH | nuscenes:DATAROOT "
                   "(default: the profile's benchmark, synthetic4d for RadarNeXt bases)")
    p.add_argument("--out", default=None, help="RUN_DIR (default runs/search/<name>); re-running resumes it")
    p.add_argument("--seeds", type=int, default=None, help="repeat each candidate with this many seeds "
                   "(default 1; --strategy oneshot: the profile's)")
    p.add_argument("--strategy", default=strategy, choices=("train", "oneshot"),
                   help=f"train every candidate, or one weight-sharing supernet over a depth axis (default {strategy})")
    p.add_argument("--supernet-steps", type=int, default=None,
                   help="--strategy oneshot: train the supernet this many steps (default: the profile's)")
    p.add_argument("--backend", default="local", choices=("local", "ray"), help="run trials here or as Ray Tune trials")
    p.add_argument("--retry-failed", action="store_true", help="re-run trials journaled as failed")
    p.add_argument("--address", default=None, help="with --backend ray: an existing cluster (default: start a local Ray)")
    p.set_defaults(prog=prog)
    return p


def parse(p: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse and keep the exact arguments, so search.json records the command that ran."""
    args = p.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    return args


def seed_count(seeds: int | None, strategy: str, recipe) -> int:
    """--seeds, or its default: 1, or a one-shot search the profile's `oneshot_seeds` (a seed there
    is one supernet, not one training per candidate, so a profile can afford several)."""
    if seeds is None:
        seeds = recipe.oneshot_seeds if strategy == "oneshot" else 1
    if seeds < 1:
        raise SearchSpaceError(f"--seeds {seeds}: expected a seed count >= 1")
    return seeds


def run_search(args, name: str, candidates_fn, title: str, base_label: str | None) -> int:
    """Validate every candidate first, then run the missing trials and write the reports (under the
    silence watchdog: no wait goes unexplained)."""
    with progress.watched(args.prog, enabled=not getattr(args, "no_progress", False)):
        return _run_search(args, name, candidates_fn, title, base_label)


def _run_search(args, name: str, candidates_fn, title: str, base_label: str | None) -> int:
    try:
        recipe = get_recipe(args.profile, args.base)
        candidates = candidates_fn()
        if args.strategy == "oneshot":
            supernet_overrides(candidates, hooks(args.base).field)
            if args.supernet_steps is not None and args.supernet_steps < 1:
                raise SearchSpaceError(f"--supernet-steps {args.supernet_steps}: expected a step count >= 1")
            if args.backend != "local":
                raise SearchSpaceError("--strategy oneshot trains one supernet in this process; "
                                       "--backend ray is for --strategy train")
        elif args.supernet_steps is not None:
            raise SearchSpaceError("--supernet-steps is for --strategy oneshot (--strategy train trains each "
                                   "candidate for the profile's schedule)")
        args.seeds = seed_count(args.seeds, args.strategy, recipe)
    except (SearchSpaceError, KeyError) as err:
        sys.exit(str(err).strip("'\""))
    args.data = args.data or recipe.data
    run_dir = Path(args.out or Path("runs") / "search" / name)
    command = f"{args.prog} " + " ".join(shlex.quote(a) for a in args.argv)
    atomic.write_json(run_dir / "search.json", {"title": title, "base": args.base, "base_label": base_label,
                                                "profile": args.profile, "data": args.data, "seeds": args.seeds,
                                                "strategy": args.strategy, "command": command,
                                                "candidates": [c["label"] for c in candidates]})
    trials = [make_trial(args.base, c, args.profile, args.data, seed, args.strategy, args.supernet_steps)
              for c in candidates for seed in range(args.seeds)]
    if args.strategy == "oneshot":
        for seed in range(args.seeds):
            run_oneshot(args.base, [t for t in trials if t["seed"] == seed], run_dir, args.retry_failed)
    elif args.backend == "ray":
        run_ray(trials, run_dir, args.address, args.retry_failed)
    else:
        run_local(trials, run_dir, args.retry_failed)
    out = write_reports(run_dir)
    print((run_dir / "report.md").read_text())
    print(f"reports in {run_dir}: " + ", ".join(out["files"]))
    return 0

"""Cheap remedies for a weak ranking study, measured without training anything:

    python -m search.nas.remedies RUN_DIR [--profile quick] [--val-samples 100,400]
                                  [--calibration-batches 8,32]

For each (val maps M, recalibration batches N) it re-scores the study's subnets (RUN_DIR/
ranking.json) twice: with inherited weights (the run's saved supernet, BN recalibrated on N
training batches) and with their stand-alone trials' final weights, both on the first M synthetic
val maps, and gives Kendall tau (and its exact p) between the two. M and N as the run used them
reproduce the study's figures (checked: the inherited scores must equal the journal's). More val
maps shrink the evaluation noise of both rankings; more batches steady the recalibrated BN
statistics (RD spaces).

    python -m search.nas.remedies RUN_DIR --supernet-steps 1200 [--sampling uniform|sandwich] [--name NAME]

trains (resumably) another supernet for the run's space in RUN_DIR/remedies/NAME/supernet (NAME
defaults to SAMPLING_STEPS) with the run's data, recipe, seed and start but the given SPOS steps
and sampling rule (search.nas.spos: uniform, or the sandwich rule's largest / smallest / 2 random
cycle accumulated into one update), scores the study's subnets with the weights they inherit
from it (the run's engine: the same BN recalibration and val data) and gives Kendall tau (and
its exact p) against the study's stand-alone scores. Any space (RD or DSFEC-style).

Both write RUN_DIR/remedies.json (rescoring `rows`, extra-supernet `supernets`, each mode keeping
the other's) and RUN_DIR/remedies.md (the table of both, with the run's own study as the first row).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path

from dsfec_jax import zoo
from dsfec_jax.core import atomic
from dsfec_jax.core.environment import environment
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.modalities.rd.evaluate import evaluate_rd
from dsfec_jax.modalities.rd.predict import RDPredictor
from dsfec_jax.core.run_checkpoints import last_steps, read_state

from ..journal import Journal
from ..ranking import kendall_tau, tau_p_value
from ..recipes import get_recipe
from .engines import PROFILES, RD_ENGINE, rd_benchmark, supernet
from .run import accumulated_seconds
from .space import from_key
from .spaces import get_space
from .spos import SAMPLINGS, SubnetScorer
from .standalone import SUBDIR

METRIC = "mAP50"


def standalone_predictors(run_dir: Path, keys: list[str]) -> dict[str, RDPredictor]:
    """subnet key -> an RD predictor with its stand-alone trial's final weights."""
    records = {r["label"]: r for r in Journal(run_dir / SUBDIR).records() if r.get("status") == "ok"}
    out = {}
    for key in keys:
        if key not in records:
            raise ValueError(f"{run_dir / SUBDIR}: no finished stand-alone trial for subnet {key}")
        r = records[key]
        trial_dir = run_dir / SUBDIR / "trials" / r["key"]
        found = last_steps(trial_dir)
        if not found:
            raise ValueError(f"{trial_dir}: no checkpoint to score")
        state = read_state(found[-1])
        det = zoo.create(r["base"], **r["overrides"], **get_recipe(r["recipe"], r["base"]).model_overrides())
        out[key] = RDPredictor(det, {"params": state["params"], "batch_stats": state["batch_stats"]})
    return out


def run_space(run_dir: Path) -> str:
    """The space the run's supernet was trained for (RUN_DIR/supernet/run.json), else yolov8n_adapter."""
    path = run_dir / "supernet" / "run.json"
    return json.loads(path.read_text()).get("space", "yolov8n_adapter") if path.exists() else "yolov8n_adapter"


def _supernet_seconds(run_dir: Path, this_process_s: float) -> float:
    """The extra supernet's wall time, kept in its RUN_DIR/remedies/NAME/timing.json (a lower
    bound after a kill: run.accumulated_seconds)."""
    return accumulated_seconds(run_dir / "timing.json", "supernet_s", this_process_s)


def supernet_remedy(run_dir: Path, space_name: str, profile: str, seed: int, steps: int, sampling: str,
                    name: str | None, command: str, progress: bool = False, log=print) -> dict:
    """Train (or resume) another supernet for the run (RUN_DIR/remedies/NAME) and score the ranking
    study's subnets with it -> the remedies.json row (tau and p against the study's stand-alone scores)."""
    from .engines import engine_for

    study = json.loads((run_dir / "ranking.json").read_text())
    keys, standalone = [pair["key"] for pair in study["pairs"]], [pair["standalone"] for pair in study["pairs"]]
    space, name = get_space(space_name), name or f"{sampling}_{steps}"
    here = run_dir / "remedies" / name
    t0 = time.perf_counter()
    engine = engine_for(space)(space, dataclasses.replace(PROFILES[profile], supernet_steps=steps), profile, here,
                               seed, progress, sampling=sampling)
    supernet_s = _supernet_seconds(here, time.perf_counter() - t0)
    if engine.metric != study["metric"]:
        raise ValueError(f"the engine ranks by {engine.metric}, the study by {study['metric']}")
    t1 = time.perf_counter()
    inherited = [s[engine.metric] for s in engine.scorer([from_key(k) for k in keys])]
    tau = kendall_tau(inherited, standalone)
    p_value = tau_p_value(inherited, standalone)
    top = max(range(len(keys)), key=lambda i: (inherited[i], keys[i]))
    by_alone = sorted(range(len(keys)), key=lambda i: -standalone[i])
    row = {"name": name, "supernet_dir": str(here / "supernet"), "sampling": sampling, "supernet_steps": steps,
           "supernet_s": supernet_s, "scoring_s": round(time.perf_counter() - t1, 1), "seed": seed,
           "calibration": engine.calibration, "data": engine.data, "subnets": keys, "inherited": inherited,
           "standalone": standalone, "tau": round(tau, 4), "p_value": None if p_value is None else round(p_value, 4),
           "top_inherited": keys[top], "top_inherited_standalone_rank": by_alone.index(top) + 1,
           "command": command, "environment": environment()}
    log(f"{name}: {steps} {sampling} SPOS steps ({supernet_s:.0f} s); Kendall tau {tau:+.2f} "
        f"(p {row['p_value']}); top inherited {keys[top]} (stand-alone rank {row['top_inherited_standalone_rank']} "
        f"of {len(keys)}); inherited {min(inherited):.2f}-{max(inherited):.2f}")
    return row


def write_results(run_dir: Path, **changes) -> dict:
    """RUN_DIR/remedies.json updated with `changes` (`rows` replace the rescoring rows; a `supernet`
    row replaces the one of its name or is appended), and RUN_DIR/remedies.md rewritten from it."""
    path = run_dir / "remedies.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    row = changes.pop("supernet", None)
    data.update(changes)
    if row is not None:
        data["supernets"] = [r for r in data.get("supernets", []) if r["name"] != row["name"]] + [row]
    atomic.write_json(path, data)
    atomic.write_text(run_dir / "remedies.md", markdown(run_dir, data))
    return data


def markdown(run_dir: Path, data: dict) -> str:
    study = json.loads((run_dir / "ranking.json").read_text())
    metric, pairs = study["metric"], study["pairs"]
    top = max(pairs, key=lambda p: (p["inherited"], p["key"]))
    rank = sorted(pairs, key=lambda p: -p["standalone"]).index(top) + 1
    lines = [f"# Ranking remedies ({len(pairs)} subnets of {run_dir}/ranking.json, inherited against stand-alone "
             f"{metric})", "", "| remedy | supernet steps | supernet wall s | Kendall tau | p | top inherited subnet "
             "(its stand-alone rank) | inherited range |", "|---|---|---|---|---|---|---|",
             f"| the run's supernet (uniform) | {_run_steps(run_dir)} | | {_signed(study['tau'])} | {study['p_value']} | "
             f"{top['key']} ({rank}) | {min(p['inherited'] for p in pairs):.2f}-{max(p['inherited'] for p in pairs):.2f} |"]
    for r in data.get("supernets", []):
        lines.append(f"| {r['name']}: {r['sampling']} sampling | {r['supernet_steps']} | {r['supernet_s']:.0f} | "
                     f"{_signed(r['tau'])} | {r['p_value']} | {r['top_inherited']} ({r['top_inherited_standalone_rank']}) | "
                     f"{min(r['inherited']):.2f}-{max(r['inherited']):.2f} |")
    for r in data.get("rows", []):
        lines.append(f"| rescored: {r['val_samples']} val, {r['calibration_batches']} recalibration batches | "
                     f"{_run_steps(run_dir)} | | {_signed(r['tau'])} | {r['p_value']} | | "
                     f"{min(r['inherited']):.2f}-{max(r['inherited']):.2f} |")
    for r in data.get("supernets", []):
        lines += ["", f"{r['name']}: `{r['command']}` (seed {r['seed']}, {r['environment'].get('versions')})"]
        lines += ["", f"| subnet | stand-alone {metric} | inherited {metric} |", "|---|---|---|"]
        lines += [f"| {k} | {a:.2f} | {i:.2f} |" for k, a, i in zip(r["subnets"], r["standalone"], r["inherited"])]
    return "\n".join(lines) + "\n"


def _signed(tau) -> str:
    """Kendall tau for the table; undefined (None, or nan when a ranking is all ties) as n/a."""
    return "n/a" if tau is None or tau != tau else f"{tau:+.2f}"


def _run_steps(run_dir: Path):
    path = run_dir / "supernet" / "run.json"
    return json.loads(path.read_text()).get("steps") if path.exists() else None


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = argparse.ArgumentParser(prog="python -m search.nas.remedies", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir")
    p.add_argument("--space", default=None, help="default: the run's (RUN_DIR/supernet/run.json)")
    p.add_argument("--profile", default="quick", choices=sorted(PROFILES), help="the profile the run used")
    p.add_argument("--seed", type=int, default=0, help="the seed the run used")
    p.add_argument("--val-samples", default="100,400")
    p.add_argument("--calibration-batches", default="8,32")
    p.add_argument("--supernet-steps", type=int, default=None,
                   help="train another supernet of this many SPOS steps and score the study's subnets with it")
    p.add_argument("--sampling", default="uniform", choices=SAMPLINGS, help="with --supernet-steps: its sampling rule")
    p.add_argument("--name", default=None, help="with --supernet-steps: RUN_DIR/remedies/NAME (default SAMPLING_STEPS)")
    p.add_argument("--progress", action="store_true")
    args = p.parse_args(argv)
    run_dir, prof = Path(args.run_dir), PROFILES[args.profile]
    space = get_space(args.space or run_space(run_dir))
    command = shlex.join(["python", "-m", "search.nas.remedies", *argv])
    if not (run_dir / "ranking.json").exists():
        raise SystemExit(f"{run_dir}/ranking.json: no ranking study (run python -m search.nas ... --standalone K first)")
    if args.supernet_steps is not None:
        if args.supernet_steps < 1:
            p.error("--supernet-steps takes a count >= 1")
        row = supernet_remedy(run_dir, space.name, args.profile, args.seed, args.supernet_steps, args.sampling,
                              args.name, command, args.progress)
        write_results(run_dir, supernet=row)
        return 0
    if space.engine is not RD_ENGINE:  # what follows re-scores the RD engine's supernet and data
        raise SystemExit(f"--val-samples / --calibration-batches re-score RD runs only ({space.name} is not); "
                         "--supernet-steps works for every space")
    study = json.loads((run_dir / "ranking.json").read_text())
    keys = [pair["key"] for pair in study["pairs"]]
    val_counts = [int(v) for v in args.val_samples.split(",")]
    batch_counts = [int(v) for v in args.calibration_batches.split(",")]
    val_all = load_rd_samples(rd_benchmark(space), "val", max(val_counts))
    train, _, (det, subnet_inputs, state) = supernet(space, prof, run_dir, args.seed, progress=False)
    alone = standalone_predictors(run_dir, keys)
    inherited_journal = {r["key"]: r[METRIC] for r in Journal(run_dir).records() if r.get("status") == "ok"}
    # the study's inherited scores are the journal's: the run's own setting must reproduce them
    rows = []
    for m in val_counts:
        val = [val_all[i] for i in range(m)]
        standalone = [evaluate_rd(alone[k], val)[0][METRIC] for k in keys]
        for n in batch_counts:
            scorer = SubnetScorer(det, subnet_inputs, state, train, val, args.seed, n, prof.batch_size)
            inherited = [s[METRIC] for s in scorer([from_key(k) for k in keys])]
            if m == prof.val_samples and n == prof.calibration_batches:  # the run's own setting: its figures
                drift = max([abs(a - inherited_journal[k]) for a, k in zip(inherited, keys)] +
                            [abs(a - pair["standalone"]) for a, pair in zip(standalone, study["pairs"])])
                if drift > 1e-3:
                    raise ValueError(f"the run's own setting (M {m}, N {n}) re-scored the subnets {drift:.4f} points "
                                     "away from the journal: not the run's supernet or data")
            tau = kendall_tau(inherited, standalone)
            rows.append({"val_samples": m, "calibration_batches": n, "tau": round(tau, 4),
                         "p_value": tau_p_value(inherited, standalone), "inherited": inherited,
                         "standalone": standalone})
            print(f"val maps {m:4d}, recalibration batches {n:3d}: Kendall tau {tau:+.2f} "
                  f"(p {rows[-1]['p_value']:.3f}); stand-alone {min(standalone):.1f}-{max(standalone):.1f}, "
                  f"inherited {min(inherited):.1f}-{max(inherited):.1f}")
    write_results(run_dir, subnets=keys, metric=METRIC, rows=rows, command=command, environment=environment())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

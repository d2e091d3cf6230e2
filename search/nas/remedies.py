"""Cheap remedies for a weak ranking study, measured without training anything:

    python -m search.nas.remedies RUN_DIR [--profile quick] [--val-samples 100,400]
                                  [--calibration-batches 8,32]

For each (val maps M, recalibration batches N) it re-scores the study's subnets (RUN_DIR/
ranking.json) twice: with inherited weights (the run's saved supernet, BN recalibrated on N
training batches) and with their stand-alone trials' final weights, both on the first M synthetic
val maps, and gives Kendall tau (and its exact p) between the two. M and N as the run used them
reproduce the study's figures (checked: the inherited scores must equal the journal's). More val
maps shrink the evaluation noise of both rankings; more batches steady the recalibrated BN
statistics. Longer supernet training, sandwich sampling and in-place distillation need new
supernets: they are SPOS training changes, not rescoring. Writes RUN_DIR/remedies.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dsfec_jax import zoo
from dsfec_jax.core import atomic, checkpoint
from dsfec_jax.core.environment import environment
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.evaluate_rd import evaluate_rd
from dsfec_jax.predict_rd import RDPredictor
from dsfec_jax.train.loop import checkpoints

from ..journal import Journal
from ..ranking import kendall_tau, tau_p_value
from ..recipes import get_recipe
from .run import PROFILES, supernet
from .space import from_key
from .spaces import get_space
from .spos import SubnetScorer
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
        found = checkpoints(trial_dir)
        if not found:
            raise ValueError(f"{trial_dir}: no checkpoint to score")
        state = checkpoint.load(found[-1])
        det = zoo.create(r["base"], **r["overrides"], **get_recipe(r["recipe"], r["base"]).model_overrides())
        out[key] = RDPredictor(det, {"params": state["params"], "batch_stats": state["batch_stats"]})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m search.nas.remedies", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir")
    p.add_argument("--space", default="yolov8n_adapter")
    p.add_argument("--profile", default="quick", choices=sorted(PROFILES), help="the profile the run used")
    p.add_argument("--seed", type=int, default=0, help="the seed the run used")
    p.add_argument("--val-samples", default="100,400")
    p.add_argument("--calibration-batches", default="8,32")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    run_dir, prof, space = Path(args.run_dir), PROFILES[args.profile], get_space(args.space)
    if not (run_dir / "ranking.json").exists():
        raise SystemExit(f"{run_dir}/ranking.json: no ranking study (run python -m search.nas ... --standalone K first)")
    study = json.loads((run_dir / "ranking.json").read_text())
    keys = [pair["key"] for pair in study["pairs"]]
    val_counts = [int(v) for v in args.val_samples.split(",")]
    batch_counts = [int(v) for v in args.calibration_batches.split(",")]
    val_all = load_rd_samples("synthetic", "val", max(val_counts))
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
    atomic.write_json(run_dir / "remedies.json", {"subnets": keys, "metric": METRIC, "rows": rows,
                                                  "command": "python -m search.nas.remedies " + " ".join(
                                                      sys.argv[1:] if argv is None else argv),
                                                  "environment": environment()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

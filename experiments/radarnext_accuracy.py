"""RadarNeXt accuracy record: gather trained runs into one reproducible table.

    python -m experiments.radarnext_accuracy RUN_DIR [RUN_DIR ...] [--out FILE]

Each RUN_DIR is a `dsfec train` directory (run.json, metrics.jsonl) and may hold `test.json`,
the output of `dsfec eval --json` on its best checkpoint. The record keeps, per run, the exact
training command, seed, steps, data, software versions, every validation evaluation (VoD 3D AP,
entire area and corridor) and the test evaluation, so a figure of docs/radarnext.md can be traced to the run
that produced it. Prints a Markdown table; --out writes the JSON atomically.

    python -m experiments.radarnext_accuracy RUN_DIR --out FILE --append

adds RUN_DIR to an existing record (a run of the same directory is replaced) without needing the
older run directories: run directories live under the ignored `runs/`, the record is shipped.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dsfec_jax.core.atomic import write_json


def read_run(run_dir: Path) -> dict:
    info_path = run_dir / "run.json"
    if not info_path.is_file():
        raise SystemExit(f"{run_dir}: no run.json (expected a `dsfec train --run-dir` directory)")
    info = json.loads(info_path.read_text())
    evals = []
    for n, line in enumerate((run_dir / "metrics.jsonl").read_text().splitlines(), 1):
        row = json.loads(line)
        if "eval" in row:
            if "mAP" not in row["eval"]:
                raise SystemExit(f"{run_dir}/metrics.jsonl line {n}: evaluation without 'mAP' (not a VoD-metric run)")
            evals.append({"step": row["step"], **row["eval"]})
    test_path = run_dir / "test.json"
    try:
        test = json.loads(test_path.read_text()) if test_path.is_file() else None
    except json.JSONDecodeError as err:
        raise SystemExit(f"{test_path}: not JSON ({err}); expected the output of `dsfec eval --json`") from err
    return {"run_dir": str(run_dir), "model": info["model"], "command": info.get("command"), "seed": info["seed"],
            "steps": info["steps"], "data": info.get("data"), "train_frames": info["train_frames"],
            "val_frames": info["val_frames"], "versions": info["versions"], "val": evals, "test": test}


def markdown(runs: list[dict]) -> str:
    lines = ["| model | steps | val mAP (corridor) | test mAP (corridor) | test AP per class |", "|---|---|---|---|---|"]
    for r in runs:
        last = r["val"][-1] if r["val"] else None
        val = f"{last['mAP']:.2f} ({last['mAP_corridor']:.2f})" if last else "-"
        t = r["test"]
        test = f"{t['mAP']:.2f} ({t['mAP_corridor']:.2f}), {t['frames']} frames" if t else "-"
        # a class without ground truth in the frames has AP NaN and is left out (as from the mAP)
        per_class = ", ".join(f"{c} {ap:.2f}" for c, ap in t["AP"].items() if ap == ap) if t else "-"
        lines.append(f"| {r['model']} | {r['steps']} | {val} | {test} | {per_class} |")
    return "\n".join(lines)


def merged(record_path: Path, runs: list[dict], command: str) -> dict:
    """The record at `record_path` with `runs` added; its invocations are kept in order."""
    try:
        old = json.loads(record_path.read_text())
        old_runs, commands = old["runs"], old["commands"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as err:
        raise SystemExit(f"{record_path}: cannot append to it ({err!r}); expected a record written by --out") from err
    new_dirs = {r["run_dir"] for r in runs}
    return {"commands": [*commands, command], "runs": [r for r in old_runs if r["run_dir"] not in new_dirs] + runs}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.radarnext_accuracy", description=__doc__.split("\n")[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--append", action="store_true", help="add the runs to the existing record --out")
    args = p.parse_args(argv)
    if args.append and args.out is None:
        p.error("--append needs --out FILE (the record to add to)")
    runs = [read_run(r) for r in args.runs]
    command = "python -m experiments.radarnext_accuracy " + " ".join(sys.argv[1:] if argv is None else argv)
    record = merged(args.out, runs, command) if args.append else {"commands": [command], "runs": runs}
    print(markdown(record["runs"]))
    if args.out:
        write_json(args.out, record)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

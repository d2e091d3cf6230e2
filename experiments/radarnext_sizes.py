"""RadarNeXt sizes and the cost of re-parameterization: python -m experiments.radarnext_sizes

1. Parameters of every registered RadarNeXt variant (Tables I-II) and of the DCNv3 placements of
   Table III, counted on the deployed form (MobileOne branches fused, no corner head), beside the
   paper's column; the train-time count is shown too.
2. Batch-1 CPU latency of the Rep-DWC backbone and of the whole network, branched (train form,
   eval mode) against fused, timed in one interleaved loop (the paper: fusion makes it faster).

Flags: --out FILE writes {command, seed, environment, rows, latency} as JSON (atomically);
--repeats N; --no-latency; --grid vod|small (small = 12.8 m x 12.8 m, for a quick look).
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import json
import sys

import jax

from dsfec_jax import zoo
from dsfec_jax.core.atomic import write_text
from dsfec_jax.core.grid import VOD_GRID, Grid
from dsfec_jax.profile import counting, latency
from dsfec_jax.core.environment import environment
from dsfec_jax.models.radarnext.paper import TABLE2, TABLE3
from dsfec_jax.modalities.registry import modality_of

SMALL_GRID = Grid((0.0, 12.8), (-6.4, 6.4), (-3.0, 2.0), 0.16)
SEED = 0


def params(name: str, **overrides) -> tuple[int, int]:
    """(deployed, train-time) parameter counts, from shapes only."""
    det = zoo.create(name, **overrides)
    shapes = jax.eval_shape(det.init, jax.random.key(SEED))
    fused_det = zoo.Detector(zoo.deploy_config(det.config))
    fused = jax.eval_shape(fused_det.init, jax.random.key(SEED))
    return counting.count_params(fused)["total"], counting.count_params(shapes)["total"]


def size_rows() -> list[dict]:
    rows = []
    for name, ref in TABLE2.items():
        deployed, train = params(name)
        rows.append({"table": "I-II", "config": name, "params": deployed, "train_params": train, "paper": ref["params"]})
    for positions, ref in TABLE3.items():
        deployed, train = params("radarnext_mdfen", dcn_positions=positions)
        label = "dcn " + "".join("①②③④⑤"[p - 1] for p in positions)
        rows.append({"table": "III", "config": label, "params": deployed, "train_params": train, "paper": ref["params"]})
    return rows


def size_markdown(rows: list[dict]) -> str:
    lines = ["| table | config | params deployed, ours (paper) | Δ vs paper | train-time params |", "|---|---|---|---|---|"]
    for r in rows:
        delta = r["params"] - r["paper"]
        lines.append(f"| {r['table']} | {r['config']} | {r['params'] / 1e6:.3f} M ({r['paper'] / 1e6:.3f} M) "
                     f"| {delta / 1e3:+.1f} k | {r['train_params'] / 1e6:.3f} M |")
    return "\n".join(lines)


def latency_suites(names: list[str], grid: Grid) -> dict:
    """name/form -> {backbone, total}: zero-argument timed callables, branched and fused."""
    suites = {}
    for name in names:
        det = zoo.create(name, grid=grid)
        variables = det.init(jax.random.key(SEED))
        fused_det, fused = zoo.deploy(det, variables)
        inputs = det.dummy_inputs(1)
        for form, d, v in (("branched", det, variables), ("fused", fused_det, fused)):
            calls = latency.stage_functions(d, v, inputs, modality_of(d.config).latency_stages)
            suites[f"{name}/{form}"] = {"backbone": calls["backbone"], "total": calls["total"]}
    return suites


def latency_markdown(times: dict, names: list[str]) -> str:
    lines = ["| model | backbone ms branched → fused | speed-up | whole network ms branched → fused | speed-up |",
             "|---|---|---|---|---|"]
    for n in names:
        b, f = times[f"{n}/branched"], times[f"{n}/fused"]
        bb, fb = b["backbone"]["median_ms"], f["backbone"]["median_ms"]
        bt, ft = b["total"]["median_ms"], f["total"]["median_ms"]
        lines.append(f"| {n} | {bb:.1f} → {fb:.1f} | {bb / fb:.2f}x | {bt:.1f} → {ft:.1f} | {bt / ft:.2f}x |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.radarnext_sizes", description=__doc__.splitlines()[0])
    p.add_argument("--out", default=None)
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--no-latency", action="store_true")
    p.add_argument("--grid", choices=("vod", "small"), default="vod")
    args = p.parse_args(argv)
    rows = size_rows()
    print(size_markdown(rows))
    payload = {"command": "python -m experiments.radarnext_sizes " + " ".join(sys.argv[1:] if argv is None else argv),
               "seed": SEED, "environment": environment(), "rows": rows}
    if not args.no_latency:
        names = zoo.available("radarnext")
        names = [n for n in names if not n.endswith("_dense")]
        grid = VOD_GRID if args.grid == "vod" else SMALL_GRID
        times = latency.time_interleaved(latency_suites(names, grid), repeats=args.repeats)
        print(f"\nBatch-1 latency on this CPU, {grid.shape[0]}x{grid.shape[1]} grid, "
              f"{zoo.config(names[0]).max_pillars} pillar slots, {args.repeats} interleaved repeats (medians):")
        print(latency_markdown(times, names))
        payload.update(latency=times, grid=args.grid, repeats=args.repeats)
    if args.out:
        write_text(args.out, json.dumps(payload, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

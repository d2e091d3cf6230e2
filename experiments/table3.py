"""DSFEC Table 3 (stage-2 blocks of DSFEC-L, 6 vs 3): python -m experiments.table3 [--profile quick|paper]"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax.models.dsfec import paper
from search import blocks

from .common import fmt, run_table


def row(r: dict) -> list[str]:
    n = int(r["label"].split("=")[1])
    ref = paper.TABLE3[n]
    return [str(n), f"{fmt(r['car_mAP'])} ({ref['mAP']})", f"{fmt(r['gflops'])} ({ref['gflops']})",
            fmt(r["latency_ms"], 1), str(ref["raspi_ms"])]


def main(argv=None) -> int:
    header = ["stage-2 blocks", "Car mAP ours (paper)", "GFLOPs ours (paper)", "latency ms ours, CPU", "RasPi ms (paper)"]
    # the paper trained both models: train strategy (pass --strategy oneshot for the cheap ranking)
    return run_table(blocks.main, ["--stage", "2", "--values", "6,3", "--strategy", "train"], "runs/experiments/table3",
                     header, row, argv)


if __name__ == "__main__":
    raise SystemExit(main())

"""DSFEC Table 2 (stem filters 32/16/12/8, FEC f3 tied): python -m experiments.table2 [--profile quick|paper]"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax.models.dsfec import paper
from search import stem

from .common import fmt, run_table


def row(r: dict) -> list[str]:
    f = int(r["label"].split("=")[1])
    ref = paper.TABLE2[f]
    return [str(f), f"{fmt(r['car_mAP'])} ({ref['mAP']})", f"{fmt(r['gflops'])} / {ref['gflops']}",
            f"{fmt(r['memory_mb'])} ({ref['memory_mb']})"]


def main(argv=None) -> int:
    header = ["stem filters", "Car mAP ours (paper)", "GFLOPs: model ours / stem paper", "memory MB ours (paper)"]
    return run_table(stem.main, ["--values", "32,16,12,8"], "runs/experiments/table2", header, row, argv)


if __name__ == "__main__":
    raise SystemExit(main())

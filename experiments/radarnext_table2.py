"""RadarNeXt Table II (Dense vs Rep-DWC backbone under the FPN, PAN and MDFEN necks), trained and
measured by the search tooling on the synthetic 4D benchmark:

    python -m experiments.radarnext_table2 [--profile smoke|quick|paper] [--out RUN_DIR]

Params are counted on the fused (deployed) form; our latency is batch-1 CPU, where the paper
gives FPS on an RTX A4000 and a Jetson AGX Orin.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax.models.radarnext.paper import TABLE2
from search import grid

from .common import fmt, run_table


def paper_key(label: str) -> str:
    """'neck=fpn backbone=dense' -> 'radarnext_fpn_dense' (TABLE2's key)."""
    fields = dict(part.split("=") for part in label.split())
    return f"radarnext_{fields['neck']}" + ("_dense" if fields["backbone"] == "dense" else "")


def row(r: dict) -> list[str]:
    ref = TABLE2[paper_key(r["label"])]
    return [paper_key(r["label"]), f"{fmt(r['params'], 3)} ({ref['params'] / 1e6:.3f})",
            f"{fmt(r['mAP'])} ({ref['mAP']})", fmt(r["mAP_corridor"]), fmt(r["latency_ms"], 1),
            f"{ref['fps_a4000']} / {ref['fps_orin']}"]


def main(argv=None) -> int:
    header = ["variant", "params M ours (paper)", "VoD mAP ours (paper)", "corridor mAP ours",
              "latency ms ours, CPU", "FPS A4000 / Orin (paper)"]
    axes = ["--base", "radarnext_mdfen", "--axis", "neck=fpn,pan,mdfen", "--axis", "backbone=dense,rep_dwc",
            "--base-label", "neck=mdfen backbone=rep_dwc"]
    return run_table(grid.main, axes, "runs/experiments/radarnext_table2", header, row, argv)


if __name__ == "__main__":
    raise SystemExit(main())

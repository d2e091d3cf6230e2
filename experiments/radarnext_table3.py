"""RadarNeXt Table III (DCNv3 positions of the MDFEN neck, Figure 2 numbering), trained and
measured by the search tooling on the synthetic 4D benchmark:

    python -m experiments.radarnext_table3 [--profile smoke|quick|paper] [--out RUN_DIR]

Position 3 fits no single feature map of the public neck by its parameter count (docs/radarnext.md,
the parameter table); ours places it on the backbone's 64-channel output.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

from dsfec_jax.models.radarnext.paper import TABLE3
from search import grid

from .common import fmt, run_table

POSITIONS = "1|3|5|2|4|1,2,4"  # the paper's row order


def positions(label: str) -> tuple[int, ...]:
    """'dcn_positions=1,2,4' -> (1, 2, 4) (TABLE3's key)."""
    return tuple(int(p) for p in label.split("=")[1].split(","))


def row(r: dict) -> list[str]:
    key = positions(r["label"])
    ref = TABLE3[key]
    return ["".join("①②③④⑤"[p - 1] for p in key), f"{fmt(r['params'], 3)} ({ref['params'] / 1e6:.3f})",
            f"{fmt(r['mAP'])} ({ref['mAP']})", fmt(r["mAP_corridor"]), fmt(r["latency_ms"], 1),
            f"{ref['fps_a4000']} / {ref['fps_orin']}"]


def main(argv=None) -> int:
    header = ["DCNv3 at", "params M ours (paper)", "VoD mAP ours (paper)", "corridor mAP ours",
              "latency ms ours, CPU", "FPS A4000 / Orin (paper)"]
    axes = ["--base", "radarnext_mdfen", "--axis", f"dcn_positions={POSITIONS}", "--base-label", "dcn_positions=4"]
    return run_table(grid.main, axes, "runs/experiments/radarnext_table3", header, row, argv)


if __name__ == "__main__":
    raise SystemExit(main())

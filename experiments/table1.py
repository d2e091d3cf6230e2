"""DSFEC Table 1 (the four models): python -m experiments.table1 [--profile-again]

Sizes and latency from the profiler's records (or a fresh profile), accuracy from the shipped
weights' manifests, each beside the paper's numbers.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import json

from dsfec_jax.models.dsfec import paper
from dsfec_jax.modalities.points.zoo_table import TABLE as ZOO_TABLE
from dsfec_jax.profile.zoo_table import shipped_accuracy

MODELS = ("baseline", "dsfec_l", "dsfec_m", "dsfec_s")


def table(records: list[dict]) -> str:
    by = {r["model"]: r for r in records}
    lines = ["| model | Car mAP ours (paper) | Car AP@4 ours (paper) | GFLOPs ours (paper) | params ours (paper) "
             "| latency ms ours, CPU | RasPi ms (paper) |", "|---|---|---|---|---|---|---|"]
    for m in MODELS:
        r, ref, acc = by.get(m), paper.TABLE1[m], shipped_accuracy(m)
        if r is None:
            continue
        ours_map = f"{acc['car_mAP']:.1f}" if acc else "-"
        ours_ap4 = f"{acc['car_AP4']:.1f}" if acc else "-"
        lat = f"{r['latency_ms']:.1f}" if r.get("latency_ms") else "-"
        lines.append(f"| {m} | {ours_map} ({ref['mAP']}) | {ours_ap4} ({ref['AP4']}) | {r['gflops']:.2f} ({ref['gflops']}) "
                     f"| {r['params'] / 1e6:.3f} M ({ref['params'] / 1e6:.2f} M) | {lat} | {ref['raspi_ms']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.table1", description=__doc__.splitlines()[0])
    p.add_argument("--profile-again", action="store_true", help="profile now instead of reading the records")
    args = p.parse_args(argv)
    if args.profile_again:
        from dsfec_jax.modalities.registry import modality_of
        from dsfec_jax.profile.records import detectors_for, profile
        records = profile(detectors_for(list(MODELS)), modality_of=modality_of)
    else:
        records = json.loads(ZOO_TABLE.record.read_text())["records"]
    print(table(records))
    print("\nAccuracy: synthetic test split (nuScenes metric); the paper's is nuScenes val. "
          "'-': no shipped weights for that model yet.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

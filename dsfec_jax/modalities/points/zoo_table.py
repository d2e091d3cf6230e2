"""The point-cloud models' README zoo table (profile/zoo_table.py generates it from records/zoo.json)."""

from __future__ import annotations

from ...profile.zoo_table import RECORDS_DIR, latency_text, rows_table
from ..base import ZooTable

NOTE = ("Car mAP / AP@4 (%, nuScenes metric) on the synthetic test split come from the manifests of the "
        "shipped weights (`dsfec_jax/weights/*.json`, which record the training command, seed and versions); "
        "'-' means no weights are shipped yet.")


def rows(recs: list[dict]) -> str:
    def row(r, acc):
        m, ap4 = (f"{acc['car_mAP']:.1f}", f"{acc['car_AP4']:.1f}") if acc else ("-", "-")
        return (f"| {r['model']} | {m} | {ap4} | {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | "
                f"{r['xla_gflops']:.2f} | {r['memory_mb']:.2f} | {latency_text(r)} | {r['notes']} |")

    return rows_table("| model | Car mAP | Car AP@4 | params | GFLOPs (2xMAC) | XLA GFLOPs | memory MB (Table 2 conv.) "
                      "| latency ms, batch 1 (p90) | notes |", recs, row)


TABLE = ZooTable(("<!-- zoo-table:start -->", "<!-- zoo-table:end -->"), RECORDS_DIR / "zoo.json", rows, NOTE)

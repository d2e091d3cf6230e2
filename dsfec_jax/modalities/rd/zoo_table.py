"""The range-Doppler models' README zoo table (profile/zoo_table.py generates it from records/zoo_rd.json)."""

from __future__ import annotations

from ...profile.zoo_table import RECORDS_DIR, latency_text, percent_text, rows_table, stages_text, xla_text
from ..base import ZooTable

STAGES = ("backbone", "adapter", "neck", "head")
NOTE = ("Range-Doppler models on 256 x 64 maps; params trainable and BN-folded (ultralytics' fuse(), the "
        "YOLOv8-Adapter paper's convention); GFLOPs 2 x MACs of the conv layers per stage (thop's convention; "
        "backbone / adapter / neck / head); mAP@50 and mAP@50-95 (%, pycocotools) on the synthetic RD test "
        "split from the manifests of the shipped weights (`dsfec_jax/weights/*.json`); '-' means no weights "
        "are shipped yet.")


def rows(recs: list[dict]) -> str:
    def row(r, acc):
        return (f"| {r['model']} | {percent_text(acc.get('mAP50'))} | {percent_text(acc.get('mAP50_95'))} "
                f"| {r['params'] / 1e6:.3f} M | {r['params_folded'] / 1e6:.3f} M | {r['gflops']:.3f} "
                f"| {stages_text(r, STAGES)} | {xla_text(r, 3)} | {latency_text(r)} |")

    return rows_table("| model | mAP@50 | mAP@50-95 | params | params BN-folded | GFLOPs (2xMAC) | GFLOPs backbone / "
                      "adapter / neck / head | XLA GFLOPs | latency ms, batch 1 (p90) |", recs, row)


TABLE = ZooTable(("<!-- zoo-rd-table:start -->", "<!-- zoo-rd-table:end -->"), RECORDS_DIR / "zoo_rd.json", rows, NOTE)

"""The camera models' README zoo table (profile/zoo_table.py generates it from records/zoo_camera.json)."""

from __future__ import annotations

from ...profile.zoo_table import RECORDS_DIR, latency_text, percent_text, rows_table, stages_text, xla_text
from ..base import ZooTable

STAGES = ("backbone", "head")
NOTE = ("Camera models at 416 x 416, batch 1; params trainable (BN moving statistics excluded); GFLOPs 2 x MACs "
        "of the conv layers (darknet's BFLOPs convention) per stage (backbone / head); memory by the Shuffle-YOLOv3 "
        "paper's Sec. 3.4 formula (every layer's parameters and output map, float32, MiB); VOC07 mAP@0.5 and COCO "
        "mAP@[.5:.95] (%) on the synthetic street test split from the manifests of the shipped weights; '-' "
        "means no weights are shipped yet.")


def rows(recs: list[dict]) -> str:
    def row(r, acc):
        memory = "-" if r.get("memory_mb") is None else f"{r['memory_mb']:.1f}"
        return (f"| {r['model']} | {percent_text(acc.get('mAP50'))} | {percent_text(acc.get('coco_mAP50_95'))} "
                f"| {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | {stages_text(r, STAGES)} | {xla_text(r, 2)} "
                f"| {memory} | {latency_text(r)} |")

    return rows_table("| model | VOC07 mAP@0.5 | COCO mAP@[.5:.95] | params | GFLOPs (2xMAC) | GFLOPs backbone / head "
                      "| XLA GFLOPs | memory MiB (paper formula) | latency ms, batch 1 (p90) |", recs, row)


TABLE = ZooTable(("<!-- zoo-camera-table:start -->", "<!-- zoo-camera-table:end -->"), RECORDS_DIR / "zoo_camera.json",
                 rows, NOTE)

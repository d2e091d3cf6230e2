"""Measured records beside the DSFEC paper's Tables 1-3, and range-Doppler records' parameter
counts beside the YOLOv8-Adapter paper's Tables 3-4, with relative errors."""

from __future__ import annotations

from .. import zoo
from ..models.dsfec import paper
from ..models.yolo_rd import paper as rd_paper
from .records import size_record

TABLE2_BASE = "dsfec_l"


def rel(ours, theirs) -> float:
    return ours / theirs - 1.0


def table1_rows(records: list[dict]) -> list[dict]:
    rows = []
    by_model = {r["model"]: r for r in records}
    for model, ref in paper.TABLE1.items():
        if model not in by_model:
            continue
        r = by_model[model]
        for key, ours, theirs in (("params", r["params"], ref["params"]), ("gflops", r["gflops"], ref["gflops"])):
            rows.append({"table": "1", "config": model, "metric": key, "paper": theirs, "ours": ours, "rel_err": rel(ours, theirs)})
    if "baseline" in by_model and "dsfec_s" in by_model and by_model["dsfec_s"].get("latency_ms"):
        ratio = by_model["dsfec_s"]["latency_ms"] / by_model["baseline"]["latency_ms"]
        rows.append({"table": "1", "config": "dsfec_s / baseline", "metric": "latency ratio (paper: RasPi 4)",
                     "paper": paper.RASPI_S_OVER_BASELINE, "ours": ratio, "rel_err": rel(ratio, paper.RASPI_S_OVER_BASELINE)})
    return rows


def table2_rows(modality) -> list[dict]:
    """Table 2 (stem filters): `modality` is DSFEC's Modality record (its stage names hold 'stem')."""
    rows = []
    for filters, ref in paper.TABLE2.items():
        rec = size_record(zoo.create(TABLE2_BASE, stem_filters=filters, name=f"{TABLE2_BASE}[stem={filters}]"),
                          modality)
        stem = rec["gflops_per_stage"]["stem"]
        rows.append({"table": "2", "config": rec["model"], "metric": "memory_mb", "paper": ref["memory_mb"],
                     "ours": rec["memory_mb"], "rel_err": rel(rec["memory_mb"], ref["memory_mb"])})
        rows.append({"table": "2", "config": rec["model"], "metric": "stem gflops (not reproducible, see README)",
                     "paper": ref["gflops"], "ours": stem, "rel_err": rel(stem, ref["gflops"])})
    return rows


def table3_rows(modality) -> list[dict]:
    """Table 3 (stage-2 blocks): `modality` is DSFEC's Modality record."""
    rows = []
    for blocks, ref in paper.TABLE3.items():
        rec = size_record(zoo.create("dsfec_l", stage_blocks=(3, blocks, 6, 3), name=f"dsfec_l[stage2={blocks}]"),
                          modality)
        rows.append({"table": "3", "config": rec["model"], "metric": "gflops", "paper": ref["gflops"],
                     "ours": rec["gflops"], "rel_err": rel(rec["gflops"], ref["gflops"])})
    return rows


def rd_rows(records: list[dict]) -> list[dict]:
    """Params (M, BN-folded: ultralytics' summary, the paper's convention; models/yolo_rd/paper.py)
    of range-Doppler records beside the YOLOv8-Adapter paper's Table 3 (YOLOv8) or 4 (v9t, v10n)."""
    rows = []
    for r in (r for r in records if "params_folded" in r):
        found = [(t, ref[r["model"]]) for t, ref in (("3", rd_paper.TABLE3["RADDet"]), ("4", rd_paper.TABLE4["RADDet"]))
                 if r["model"] in ref]
        if found:
            table, ref = found[0]
            ours = r["params_folded"] / 1e6
            rows.append({"table": f"{table} (YOLOv8-Adapter)", "config": r["model"], "metric": "params M (BN-folded)",
                         "paper": ref["params"], "ours": ours, "rel_err": rel(ours, ref["params"])})
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| table | config | metric | paper | ours | rel. error |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['table']} | {r['config']} | {r['metric']} | {r['paper']:.4g} | {r['ours']:.4g} | {100 * r['rel_err']:+.1f} % |")
    return "\n".join(lines)

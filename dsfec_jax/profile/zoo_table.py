"""The README model-zoo tables, generated from profiler records (never typed by hand).

Point-cloud models (Car mAP, DSFEC's Table 2 memory), range-Doppler models (mAP@50 and @50-95,
BN-folded params, GFLOPs per stage) and camera models (VOC07 mAP@0.5, COCO mAP, the Shuffle-YOLOv3
paper's memory formula) have different columns, so they are three tables, each between its own
README markers and from its own record file: `records/zoo.json`, `records/zoo_rd.json` and
`records/zoo_camera.json`. A payload holding several kinds updates each of their tables.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from ..core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import json
import re
from pathlib import Path

from ..core import atomic
from .. import zoo

START, END = "<!-- zoo-table:start -->", "<!-- zoo-table:end -->"
RD_START, RD_END = "<!-- zoo-rd-table:start -->", "<!-- zoo-rd-table:end -->"
CAMERA_START, CAMERA_END = "<!-- zoo-camera-table:start -->", "<!-- zoo-camera-table:end -->"
RECORDS = Path(__file__).parent / "records" / "zoo.json"
RD_RECORDS = Path(__file__).parent / "records" / "zoo_rd.json"
CAMERA_RECORDS = Path(__file__).parent / "records" / "zoo_camera.json"
# modality -> README markers, record file
MARKERS = {"points": (START, END), "rd": (RD_START, RD_END), "image": (CAMERA_START, CAMERA_END)}
RECORD_FILES = {"points": RECORDS, "rd": RD_RECORDS, "image": CAMERA_RECORDS}

RD_STAGES = ("backbone", "adapter", "neck", "head")
RD_NOTE = ("Range-Doppler models on 256 x 64 maps; params trainable and BN-folded (ultralytics' fuse(), the "
           "YOLOv8-Adapter paper's convention); GFLOPs 2 x MACs of the conv layers per stage (thop's convention; "
           "backbone / adapter / neck / head); mAP@50 and mAP@50-95 (%, pycocotools) on the synthetic RD test "
           "split from the manifests of the shipped weights (`dsfec_jax/weights/*.json`); '-' means no weights "
           "are shipped yet.")
CAMERA_STAGES = ("backbone", "head")
CAMERA_NOTE = ("Camera models at 416 x 416, batch 1; params trainable (BN moving statistics excluded); GFLOPs 2 x MACs "
               "of the conv layers (darknet's BFLOPs convention) per stage (backbone / head); memory by the Shuffle-YOLOv3 "
               "paper's Sec. 3.4 formula (every layer's parameters and output map, float32, MiB); VOC07 mAP@0.5 and COCO "
               "mAP@[.5:.95] (%) on the synthetic street test split from the manifests of the shipped weights; '-' "
               "means no weights are shipped yet.")


def shipped_accuracy(model: str) -> dict | None:
    """The measured synthetic-test figures in the manifest of the model's shipped weights."""
    path = Path(str(zoo.shipped_weights(model)) + ".json")
    return json.loads(path.read_text())["measured"]["test"] if path.exists() else None


def by_modality(payload: dict) -> dict[str, dict]:
    """{modality: the payload with that modality's records only}, for the modalities it holds."""
    out = {}
    for r in payload["records"]:
        out.setdefault(zoo.FAMILIES[r["family"]].modality, {**payload, "records": []})["records"].append(r)
    return out


def markdown(payload: dict) -> str:
    """The table(s) of a payload's records, each with its footer (one table per modality)."""
    parts = by_modality(payload)
    return "\n\n".join(table_markdown(parts[m]) for m in MARKERS if m in parts)


POINT_NOTE = ("Car mAP / AP@4 (%, nuScenes metric) on the synthetic test split come from the manifests of the "
              "shipped weights (`dsfec_jax/weights/*.json`, which record the training command, seed and versions); "
              "'-' means no weights are shipped yet.")


def table_markdown(payload: dict) -> str:
    """One modality's table and footer."""
    recs = payload["records"]
    modality = zoo.FAMILIES[recs[0]["family"]].modality
    rows, note = {"points": (point_rows, POINT_NOTE), "rd": (rd_rows, RD_NOTE),
                  "image": (camera_rows, CAMERA_NOTE)}[modality]
    env = recs[0].get("latency_setup", {}) if recs else {}
    lines = [rows(recs), ""]
    lines.append(f"Measured with `{payload['command']}` on {env.get('cpu', '?')}, {_threads(env)}, "
                 f"jax {env.get('versions', {}).get('jax', '?')}; records in "
                 f"`dsfec_jax/profile/records/{RECORD_FILES[modality].name}`. " + note)
    return "\n".join(lines)


def _table(header: str, recs: list[dict], row) -> str:
    """A markdown table: `header`, its rule, then `row(record, the shipped weights' test figures or {})`
    for each record."""
    rule = "|" + "---|" * (header.count("|") - 1)
    return "\n".join([header, rule] + [row(r, shipped_accuracy(r["model"]) or {}) for r in recs])


def point_rows(recs: list[dict]) -> str:
    def row(r, acc):
        m, ap4 = (f"{acc['car_mAP']:.1f}", f"{acc['car_AP4']:.1f}") if acc else ("-", "-")
        return (f"| {r['model']} | {m} | {ap4} | {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | "
                f"{r['xla_gflops']:.2f} | {r['memory_mb']:.2f} | {_latency(r)} | {r['notes']} |")

    return _table("| model | Car mAP | Car AP@4 | params | GFLOPs (2xMAC) | XLA GFLOPs | memory MB (Table 2 conv.) "
                  "| latency ms, batch 1 (p90) | notes |", recs, row)


def rd_rows(recs: list[dict]) -> str:
    def row(r, acc):
        return (f"| {r['model']} | {_percent(acc.get('mAP50'))} | {_percent(acc.get('mAP50_95'))} "
                f"| {r['params'] / 1e6:.3f} M | {r['params_folded'] / 1e6:.3f} M | {r['gflops']:.3f} "
                f"| {_stages(r, RD_STAGES)} | {_xla(r, 3)} | {_latency(r)} |")

    return _table("| model | mAP@50 | mAP@50-95 | params | params BN-folded | GFLOPs (2xMAC) | GFLOPs backbone / "
                  "adapter / neck / head | XLA GFLOPs | latency ms, batch 1 (p90) |", recs, row)


def camera_rows(recs: list[dict]) -> str:
    def row(r, acc):
        memory = "-" if r.get("memory_mb") is None else f"{r['memory_mb']:.1f}"
        return (f"| {r['model']} | {_percent(acc.get('mAP50'))} | {_percent(acc.get('coco_mAP50_95'))} "
                f"| {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | {_stages(r, CAMERA_STAGES)} | {_xla(r, 2)} "
                f"| {memory} | {_latency(r)} |")

    return _table("| model | VOC07 mAP@0.5 | COCO mAP@[.5:.95] | params | GFLOPs (2xMAC) | GFLOPs backbone / head "
                  "| XLA GFLOPs | memory MiB (paper formula) | latency ms, batch 1 (p90) |", recs, row)


def update_readme(readme: str | Path, payload: dict) -> None:
    """Replace the table of each modality the payload holds between that modality's markers."""
    text = Path(readme).read_text()
    parts = by_modality(payload)
    for modality, part in parts.items():
        start, end = MARKERS[modality]
        if start not in text or end not in text:
            raise ValueError(f"{readme}: expected the markers {start} and {end} around the {modality!r} zoo table")
        block = f"{start}\n{table_markdown(part)}\n{end}"
        text = re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    atomic.write_text(readme, text)


def main(argv=None) -> int:
    """python -m dsfec_jax.profile.zoo_table [README.md]: rebuild the tables from the stored records
    (zoo.json; zoo_rd.json and zoo_camera.json where they exist) and the shipped weights' manifests,
    without profiling again."""
    import sys

    argv = sys.argv[1:] if argv is None else argv
    for records in RECORD_FILES.values():
        if records.exists():
            update_readme(argv[0] if argv else "README.md", json.loads(records.read_text()))
    return 0


def _latency(record: dict) -> str:
    return f"{record['latency_ms']:.1f} ({record['latency_p90_ms']:.1f})" if record.get("latency_ms") else "-"


def _stages(record: dict, stages) -> str:
    """GFLOPs of each stage, ' / '-separated ('-' for a stage the network lacks)."""
    per_stage = record["gflops_per_stage"]
    return " / ".join(f"{per_stage[s]:.3f}" if s in per_stage else "-" for s in stages)


def _xla(record: dict, digits: int) -> str:
    return f"{record['xla_gflops']:.{digits}f}" if "xla_gflops" in record else "-"


def _percent(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def _threads(env: dict) -> str:
    n = env.get("threads", "?")
    return f"{n} XLA thread{'' if n == 1 else 's'}"


if __name__ == "__main__":
    raise SystemExit(main())

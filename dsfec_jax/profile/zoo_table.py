"""The README model-zoo tables, generated from profiler records (never typed by hand).

Point-cloud models (Car mAP, DSFEC's Table 2 memory) and range-Doppler models (mAP@50 and
@50-95, BN-folded params, GFLOPs per stage) have different columns, so they are two tables, each
between its own README markers and from its own record file: `records/zoo.json` and
`records/zoo_rd.json`. A payload holding both kinds updates both tables.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from ..core import atomic
from .. import zoo

START, END = "<!-- zoo-table:start -->", "<!-- zoo-table:end -->"
RD_START, RD_END = "<!-- zoo-rd-table:start -->", "<!-- zoo-rd-table:end -->"
RECORDS = Path(__file__).parent / "records" / "zoo.json"
RD_RECORDS = Path(__file__).parent / "records" / "zoo_rd.json"
MARKERS = {"points": (START, END), "rd": (RD_START, RD_END)}  # modality -> README markers

RD_STAGES = ("backbone", "adapter", "neck", "head")
RD_NOTE = ("Range-Doppler models on 256 x 64 maps; params trainable and BN-folded (ultralytics' fuse(), the "
           "YOLOv8-Adapter paper's convention); GFLOPs 2 x MACs of the conv layers per stage (thop's convention; "
           "backbone / adapter / neck / head); mAP@50 and mAP@50-95 (%, pycocotools) on the synthetic RD test "
           "split from the manifests of the shipped weights (`dsfec_jax/weights/*.json`); '-' means no weights "
           "are shipped yet.")


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


def table_markdown(payload: dict) -> str:
    """One modality's table and footer."""
    recs = payload["records"]
    rd = zoo.FAMILIES[recs[0]["family"]].modality == "rd"
    env = recs[0].get("latency_setup", {}) if recs else {}
    lines = [rd_rows(recs) if rd else point_rows(recs), ""]
    lines.append(f"Measured with `{payload['command']}` on {env.get('cpu', '?')}, {_threads(env)}, "
                 f"jax {env.get('versions', {}).get('jax', '?')}; records in "
                 f"`dsfec_jax/profile/records/{(RD_RECORDS if rd else RECORDS).name}`. "
                 + (RD_NOTE if rd else "Car mAP / AP@4 (%, nuScenes metric) on the synthetic "
                    "test split come from the manifests of the shipped weights (`dsfec_jax/weights/*.json`, which "
                    "record the training command, seed and versions); '-' means no weights are shipped yet."))
    return "\n".join(lines)


def point_rows(recs: list[dict]) -> str:
    lines = [
        "| model | Car mAP | Car AP@4 | params | GFLOPs (2xMAC) | XLA GFLOPs | memory MB (Table 2 conv.) "
        "| latency ms, batch 1 (p90) | notes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in recs:
        acc = shipped_accuracy(r["model"])
        m, ap4 = (f"{acc['car_mAP']:.1f}", f"{acc['car_AP4']:.1f}") if acc else ("-", "-")
        lines.append(f"| {r['model']} | {m} | {ap4} | {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | "
                     f"{r['xla_gflops']:.2f} | {r['memory_mb']:.2f} | {_latency(r)} | {r['notes']} |")
    return "\n".join(lines)


def rd_rows(recs: list[dict]) -> str:
    lines = ["| model | mAP@50 | mAP@50-95 | params | params BN-folded | GFLOPs (2xMAC) | GFLOPs backbone / adapter "
             "/ neck / head | XLA GFLOPs | latency ms, batch 1 (p90) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in recs:
        acc = shipped_accuracy(r["model"]) or {}
        stages = " / ".join(f"{r['gflops_per_stage'][s]:.3f}" if s in r["gflops_per_stage"] else "-" for s in RD_STAGES)
        xla = f"{r['xla_gflops']:.3f}" if "xla_gflops" in r else "-"
        lines.append(f"| {r['model']} | {_percent(acc.get('mAP50'))} | {_percent(acc.get('mAP50_95'))} "
                     f"| {r['params'] / 1e6:.3f} M | {r['params_folded'] / 1e6:.3f} M | {r['gflops']:.3f} | {stages} "
                     f"| {xla} | {_latency(r)} |")
    return "\n".join(lines)


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
    (zoo.json; zoo_rd.json where it exists) and the shipped weights' manifests, without profiling again."""
    import sys

    argv = sys.argv[1:] if argv is None else argv
    for records in (RECORDS, RD_RECORDS):
        if records.exists():
            update_readme(argv[0] if argv else "README.md", json.loads(records.read_text()))
    return 0


def _latency(record: dict) -> str:
    return f"{record['latency_ms']:.1f} ({record['latency_p90_ms']:.1f})" if record.get("latency_ms") else "-"


def _percent(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def _threads(env: dict) -> str:
    n = env.get("threads", "?")
    return f"{n} XLA thread{'' if n == 1 else 's'}"


if __name__ == "__main__":
    raise SystemExit(main())

"""The README model-zoo tables, generated from profiler records (never typed by hand).

Each modality's models have their own columns (point-cloud models: Car mAP, DSFEC's Table 2 memory;
range-Doppler models: mAP@50 and @50-95, BN-folded params, GFLOPs per stage; camera models: VOC07
mAP@0.5, COCO mAP, the Shuffle-YOLOv3 paper's memory formula), so each has its own table, between
its own README markers and from its own record file under `records/`: the modality's `zoo_table`
(a ZooTable: markers, record, rows, note; modalities/<m>/zoo_table.py). This module is the
machinery: the caller passes the lookup of a model's Modality record (`modality_of`), and a payload
holding several kinds updates each of their tables.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Callable, Iterable

from ..core import atomic
from .. import zoo

RECORDS_DIR = Path(__file__).parent / "records"  # where each modality's zoo table record lives


def shipped_accuracy(model: str) -> dict | None:
    """The measured synthetic-test figures in the manifest of the model's shipped weights."""
    path = Path(str(zoo.shipped_weights(model)) + ".json")
    return json.loads(path.read_text())["measured"]["test"] if path.exists() else None


def by_modality(payload: dict, modality_of: Callable[[str], Any]) -> list[tuple[Any, dict]]:
    """[(Modality record, the payload with that modality's records only)], in the order the
    modalities first appear in the records (`modality_of(model name)` -> its record)."""
    parts: dict[str, tuple[Any, dict]] = {}
    for r in payload["records"]:
        modality = modality_of(r["model"])
        parts.setdefault(modality.name, (modality, {**payload, "records": []}))[1]["records"].append(r)
    return list(parts.values())


def markdown(payload: dict, modality_of: Callable[[str], Any]) -> str:
    """The table(s) of a payload's records, each with its footer (one table per modality)."""
    return "\n\n".join(table_markdown(part, modality.zoo_table) for modality, part in by_modality(payload, modality_of))


def table_markdown(payload: dict, table) -> str:
    """One modality's table (`table`: its ZooTable) and footer."""
    recs = payload["records"]
    env = recs[0].get("latency_setup", {}) if recs else {}
    lines = [table.rows(recs), ""]
    lines.append(f"Measured with `{payload['command']}` on {env.get('cpu', '?')}, {_threads(env)}, "
                 f"jax {env.get('versions', {}).get('jax', '?')}; records in "
                 f"`dsfec_jax/profile/records/{table.record.name}`. " + table.note)
    busy = next((r["machine_load"] for r in recs if (r.get("machine_load") or {}).get("busy")), None)
    if busy:  # a table must not pass a loaded machine's latencies off as the machine's
        lines.append(f"\nLatency measured on a busy machine ({busy['text'][len('busy: '):]}): not the machine's.")
    return "\n".join(lines)


def rows_table(header: str, recs: list[dict], row) -> str:
    """A markdown table: `header`, its rule, then `row(record, the shipped weights' test figures or {})`
    for each record."""
    rule = "|" + "---|" * (header.count("|") - 1)
    return "\n".join([header, rule] + [row(r, shipped_accuracy(r["model"]) or {}) for r in recs])


def update_readme(readme: str | Path, payload: dict, modality_of: Callable[[str], Any]) -> None:
    """Replace the table of each modality the payload holds between that modality's markers."""
    text = Path(readme).read_text()
    for modality, part in by_modality(payload, modality_of):
        text = with_table(text, readme, part, modality.zoo_table, modality.name)
    atomic.write_text(readme, text)


def with_table(text: str, readme: str | Path, payload: dict, table, name: str) -> str:
    """`text` with the table of `payload` between `table`'s markers (a ValueError naming the README
    and the markers when they are missing)."""
    start, end = table.markers
    if start not in text or end not in text:
        raise ValueError(f"{readme}: expected the markers {start} and {end} around the {name!r} zoo table")
    block = f"{start}\n{table_markdown(payload, table)}\n{end}"
    return re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)


def rebuild_readme(readme: str | Path, modalities: Iterable) -> None:
    """Rebuild every table of `modalities` (Modality records) from its stored record file, where it
    exists, and the shipped weights' manifests, without profiling again
    (`python -m dsfec_jax.profile --tables-only [--readme README.md]`)."""
    text = Path(readme).read_text()
    for modality in modalities:
        if modality.zoo_table.record.exists():
            payload = json.loads(modality.zoo_table.record.read_text())
            text = with_table(text, readme, payload, modality.zoo_table, modality.name)
    atomic.write_text(readme, text)


def latency_text(record: dict) -> str:
    return f"{record['latency_ms']:.1f} ({record['latency_p90_ms']:.1f})" if record.get("latency_ms") else "-"


def stages_text(record: dict, stages) -> str:
    """GFLOPs of each stage, ' / '-separated ('-' for a stage the network lacks)."""
    per_stage = record["gflops_per_stage"]
    return " / ".join(f"{per_stage[s]:.3f}" if s in per_stage else "-" for s in stages)


def xla_text(record: dict, digits: int) -> str:
    return f"{record['xla_gflops']:.{digits}f}" if "xla_gflops" in record else "-"


def percent_text(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def _threads(env: dict) -> str:
    n = env.get("threads", "?")
    return f"{n} XLA thread{'' if n == 1 else 's'}"

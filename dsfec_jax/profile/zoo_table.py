"""The README model-zoo table, generated from profiler records (never typed by hand)."""

from __future__ import annotations

import json
import re
from pathlib import Path

from ..core import atomic
from .. import zoo

START, END = "<!-- zoo-table:start -->", "<!-- zoo-table:end -->"


def shipped_accuracy(model: str) -> dict | None:
    """The measured synthetic-test figures in the manifest of the model's shipped weights."""
    path = Path(str(zoo.shipped_weights(model)) + ".json")
    return json.loads(path.read_text())["measured"]["test"] if path.exists() else None


def markdown(payload: dict) -> str:
    recs = payload["records"]
    env = recs[0].get("latency_setup", {}) if recs else {}
    lines = [
        "| model | Car mAP | Car AP@4 | params | GFLOPs (2xMAC) | XLA GFLOPs | memory MB (Table 2 conv.) "
        "| latency ms, batch 1 (p90) | notes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in recs:
        lat = f"{r['latency_ms']:.1f} ({r['latency_p90_ms']:.1f})" if r.get("latency_ms") else "-"
        acc = shipped_accuracy(r["model"])
        m, ap4 = (f"{acc['car_mAP']:.1f}", f"{acc['car_AP4']:.1f}") if acc else ("-", "-")
        lines.append(f"| {r['model']} | {m} | {ap4} | {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | "
                     f"{r['xla_gflops']:.2f} | {r['memory_mb']:.2f} | {lat} | {r['notes']} |")
    lines.append("")
    lines.append(f"Measured with `{payload['command']}` on {env.get('cpu', '?')}, {_threads(env)}, "
                 f"jax {env.get('versions', {}).get('jax', '?')}; records in "
                 "`dsfec_jax/profile/records/zoo.json`. Car mAP / AP@4 (%, nuScenes metric) on the synthetic "
                 "test split come from the manifests of the shipped weights (`dsfec_jax/weights/*.json`, which "
                 "record the training command, seed and versions); '-' means no weights are shipped yet.")
    return "\n".join(lines)


def update_readme(readme: str | Path, payload: dict) -> None:
    text = Path(readme).read_text()
    if START not in text or END not in text:
        raise ValueError(f"{readme}: expected the markers {START} and {END} around the zoo table")
    block = f"{START}\n{markdown(payload)}\n{END}"
    text = re.sub(re.escape(START) + ".*?" + re.escape(END), lambda _: block, text, flags=re.S)
    atomic.write_text(readme, text)


RECORDS = Path(__file__).parent / "records" / "zoo.json"


def main(argv=None) -> int:
    """python -m dsfec_jax.profile.zoo_table [README.md]: rebuild the table from the stored records
    and the shipped weights' manifests, without profiling again."""
    import sys

    argv = sys.argv[1:] if argv is None else argv
    update_readme(argv[0] if argv else "README.md", json.loads(RECORDS.read_text()))
    return 0


def _threads(env: dict) -> str:
    n = env.get("threads", "?")
    return f"{n} XLA thread{'' if n == 1 else 's'}"


if __name__ == "__main__":
    raise SystemExit(main())

"""The README model-zoo table, generated from profiler records (never typed by hand)."""

from __future__ import annotations

import re
from pathlib import Path

from .. import atomic

START, END = "<!-- zoo-table:start -->", "<!-- zoo-table:end -->"


def markdown(payload: dict) -> str:
    recs = payload["records"]
    env = recs[0].get("latency_setup", {}) if recs else {}
    lines = [
        "| model | params | GFLOPs (2xMAC) | XLA GFLOPs | memory MB (Table 2 conv.) | latency ms, batch 1 (p90) | notes |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in recs:
        lat = f"{r['latency_ms']:.1f} ({r['latency_p90_ms']:.1f})" if r.get("latency_ms") else "-"
        lines.append(f"| {r['model']} | {r['params'] / 1e6:.3f} M | {r['gflops']:.2f} | {r['xla_gflops']:.2f} | "
                     f"{r['memory_mb']:.2f} | {lat} | {r['notes']} |")
    lines.append("")
    lines.append(f"Measured with `{payload['command']}` on {env.get('cpu', '?')}, {env.get('threads', '?')} "
                 f"XLA threads, jax {env.get('versions', {}).get('jax', '?')}; records in "
                 "`dsfec_jax/profile/records/zoo.json`.")
    return "\n".join(lines)


def update_readme(readme: str | Path, payload: dict) -> None:
    text = Path(readme).read_text()
    if START not in text or END not in text:
        raise ValueError(f"{readme}: expected the markers {START} and {END} around the zoo table")
    block = f"{START}\n{markdown(payload)}\n{END}"
    text = re.sub(re.escape(START) + ".*?" + re.escape(END), lambda _: block, text, flags=re.S)
    atomic.write_text(readme, text)

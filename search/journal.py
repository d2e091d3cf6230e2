"""The journal of a search: one JSON record per trial in RUN_DIR/journal.jsonl.

Every append rewrites the file atomically, so a killed run leaves either the old or the new
journal, never a torn line; a re-run skips every trial whose key already has a record.
"""

from __future__ import annotations

import json
from pathlib import Path

from dsfec_jax.core import atomic


class Journal:
    def __init__(self, run_dir: str | Path):
        self.path = Path(run_dir) / "journal.jsonl"

    def records(self) -> list[dict]:
        if not self.path.exists():
            return []
        out = []
        for n, line in enumerate(self.path.read_text().splitlines(), 1):
            if line.strip():
                try:
                    out.append(json.loads(line))
                except json.JSONDecodeError as err:
                    raise ValueError(f"{self.path}:{n}: not a JSON record ({err})") from err
        return out

    def done(self, retry_failed: bool = False) -> set[str]:
        """Keys with a record (with retry_failed, only those that succeeded)."""
        return {r["key"] for r in self.records() if not retry_failed or r["status"] == "ok"}

    def append(self, record: dict) -> None:
        self._write([r for r in self.records() if r["key"] != record["key"]] + [record])

    def update(self, record: dict) -> None:
        """Replace the record of record["key"] in place (its position kept); KeyError if it has none."""
        records = self.records()
        at = next((i for i, r in enumerate(records) if r["key"] == record["key"]), None)
        if at is None:
            raise KeyError(f"{self.path}: no record with key {record['key']!r} to update")
        records[at] = record
        self._write(records)

    def _write(self, records: list[dict]) -> None:
        atomic.write_text(self.path, "".join(json.dumps(r) + "\n" for r in records))

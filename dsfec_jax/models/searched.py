"""Subnets found by the one-shot search (`python -m search.nas ... --register`), as zoo variants.

Each family keeps its own `searched.json` beside its variants: {name: {"base": variant,
"overrides": {field: value}, "provenance": {"command": ...}}}. Its variants module reads it at
import, so a registered subnet trains, evaluates, exports and benchmarks like any other model.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path


def searched_variants(path: Path, variants: dict) -> dict:
    """The searched subnets recorded in `path` as variants of `variants` (none when it does not exist)."""
    if not path.exists():
        return {}
    try:
        entries = json.loads(path.read_text())
        out = {}
        for name, entry in entries.items():
            overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in entry["overrides"].items()}
            note = f"searched subnet of {entry['base']}: {entry['provenance']['command']}"
            out[name] = dataclasses.replace(variants[entry["base"]], name=name, notes=note, **overrides)
        return out
    except (ValueError, KeyError, TypeError) as err:
        raise ValueError(f"{path}: expected {{name: {{'base': a variant of {sorted(variants)}, 'overrides': "
                         f"{{field: value}}, 'provenance': {{'command': ...}}}}}} ({type(err).__name__}: {err})") from err

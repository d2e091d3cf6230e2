"""A searched subnet into the zoo: `zoo.create("yolov8n_adapter_search")` after a search.

The subnet's overrides and the search's provenance (command, seed, versions, its inherited-weight
score and costs) go into the family's `searched.json` (its variants module reads it at import:
models/searched.py), written atomically; an entry of the same name is replaced. The searched model then
trains, evaluates, exports and benchmarks like any other zoo model.
"""

from __future__ import annotations

import json
from pathlib import Path

from dsfec_jax.core import atomic
from dsfec_jax.core.provenance import jsonable
from dsfec_jax import zoo
from dsfec_jax.models.dsfec.variants import SEARCHED as DSFEC_SEARCHED
from dsfec_jax.models.yolo_rd.variants import SEARCHED

from .space import Genes, SearchSpace, key


def searched_file(base: str) -> Path:
    """The searched.json of `base`'s family (its variants module reads it)."""
    files = {"yolo_rd": SEARCHED, "dsfec": DSFEC_SEARCHED}
    family = zoo.family_of(base).name
    if family not in files:
        raise ValueError(f"--register: the {family} family keeps no searched subnets (known: {sorted(files)})")
    return files[family]


def register(space: SearchSpace, genes: Genes, name: str, provenance: dict, path: Path | None = None) -> dict:
    path = searched_file(space.base) if path is None else path
    entries = json.loads(path.read_text()) if path.exists() else {}
    entry = {"base": space.base, "space": space.name, "subnet": key(genes), "choices": space.decode(genes),
             "overrides": space.overrides(genes), "provenance": provenance}
    entries[name] = jsonable(entry)
    atomic.write_text(path, json.dumps(entries, indent=1) + "\n")
    return entries[name]

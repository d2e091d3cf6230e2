"""What makes a shipped record reproducible: the software versions it ran with, and a JSON-safe
copy of the configs and options that produced it."""

from __future__ import annotations

import dataclasses
import json
import platform
from importlib import metadata


def versions(packages=("jax", "jaxlib", "flax", "numpy", "optax", "dsfec_jax")) -> dict:
    """Python and package versions (None for a package that is not installed)."""
    out = {"python": platform.python_version()}
    for name in packages:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def jsonable(obj):
    """`obj` as plain JSON values: dataclasses become dicts, anything else unknown becomes str."""
    return json.loads(json.dumps(obj, default=lambda o: dataclasses.asdict(o) if dataclasses.is_dataclass(o) else str(o)))

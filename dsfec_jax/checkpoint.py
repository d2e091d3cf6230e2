"""Variables trees on disk: flax msgpack bytes written atomically, plus a JSON manifest.

Used for training checkpoints and for the weights shipped inside the package.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import flax.serialization
import jax
import numpy as np

from . import atomic


def save(path: str | os.PathLike, tree, manifest: dict | None = None) -> None:
    """Write `tree` to PATH (msgpack) and `manifest` to PATH.json, each atomically."""
    path = Path(path)
    data = flax.serialization.to_bytes(jax.tree.map(np.asarray, tree))
    atomic.write_bytes(path, data)
    if manifest is not None:
        atomic.write_json(manifest_path(path), manifest)


def load(path: str | os.PathLike, target=None):
    """Read a tree written by `save`; with `target`, restore into its structure (shapes checked)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint/weights file")
    try:
        raw = flax.serialization.msgpack_restore(path.read_bytes())
    except Exception as err:  # msgpack raises several types on corrupt input
        raise ValueError(f"{path}: not a readable msgpack variables file ({err})") from err
    if target is None:
        return raw
    restored = flax.serialization.from_state_dict(target, raw)
    for (kp, a), b in zip(jax.tree_util.tree_flatten_with_path(target)[0], jax.tree.leaves(restored)):
        if np.shape(a) != np.shape(b):
            raise ValueError(f"{path}: {jax.tree_util.keystr(kp)} has shape {np.shape(b)}, the model expects {np.shape(a)}")
    return restored


def manifest_path(path: str | os.PathLike) -> Path:
    return Path(str(path) + ".json")


def read_manifest(path: str | os.PathLike) -> dict:
    p = manifest_path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: weights manifest missing")
    return json.loads(p.read_text())

"""Variables trees on disk: flax msgpack bytes plus a JSON manifest, written as one unit.

Used for training checkpoints and for the weights shipped inside the package.

PATH (msgpack) is written first, PATH.json last, each atomically; the manifest records the
sha256 and size of PATH. So a kill between the two writes leaves a pair that `problem` names
(manifest missing, or describing the previous PATH) instead of one that loads the wrong thing.
Manifests written before checksums existed (no "sha256") still load, with shape checks only.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import flax.serialization
import jax
import numpy as np

from . import atomic

CHECKSUM_KEYS = ("sha256", "bytes")  # what save adds to a manifest


class CheckpointError(ValueError):
    """A weights/manifest pair that was not completely written (or was changed since)."""


def save(path: str | os.PathLike, tree, manifest: dict | None = None) -> None:
    """Write `tree` to PATH (msgpack), then `manifest` + PATH's checksum to PATH.json."""
    path = Path(path)
    data = flax.serialization.to_bytes(jax.tree.map(np.asarray, tree))
    atomic.write_bytes(path, data)
    atomic.write_json(manifest_path(path), {**(manifest or {}), **checksum(data)})


def checksum(data: bytes) -> dict:
    return {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}


def problem(path: str | os.PathLike, data: bytes | None = None) -> str | None:
    """Why the pair at PATH cannot be trusted, or None when it is complete (`data`: PATH's bytes,
    if already read). A legacy manifest without a checksum counts as complete."""
    path, mpath = Path(path), manifest_path(path)
    if not path.is_file():
        return f"{path}: no such checkpoint/weights file"
    if not mpath.is_file():
        return (f"{mpath}: manifest missing; it is written after {path.name}, so that file was never "
                "completely saved (killed while saving?)")
    try:
        manifest = json.loads(mpath.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        return f"{mpath}: not a readable JSON manifest ({err})"
    if not isinstance(manifest, dict):
        return f"{mpath}: expected a JSON object, found {type(manifest).__name__}"
    if "sha256" not in manifest:
        return None
    data = path.read_bytes() if data is None else data
    if checksum(data) != {k: manifest.get(k) for k in CHECKSUM_KEYS}:
        return (f"{path}: does not match its manifest {mpath.name} ({len(data)} bytes, sha256 "
                f"{hashlib.sha256(data).hexdigest()[:12]}; the manifest records {manifest.get('bytes')} bytes, "
                f"sha256 {str(manifest['sha256'])[:12]}): killed while saving, or changed since")
    return None


def load(path: str | os.PathLike, target=None):
    """Read a tree written by `save`; with `target`, restore into its structure (shapes checked).
    Raises CheckpointError when the pair is incomplete or the bytes do not match the manifest."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint/weights file")
    data = path.read_bytes()
    reason = problem(path, data)
    if reason:
        raise CheckpointError(reason)
    try:
        raw = flax.serialization.msgpack_restore(data)
    except Exception as err:  # msgpack raises several types on corrupt input
        raise ValueError(f"{path}: not a readable msgpack variables file ({err})") from err
    return raw if target is None else restored(path, raw, target)


def restored(path: str | os.PathLike, raw: dict, target, where: str = ""):
    """`raw` (a state dict read from PATH) in the structure of `target`, every shape checked;
    `where` names the subtree of PATH that `raw` is, for the message (e.g. "['ema']")."""
    tree = flax.serialization.from_state_dict(target, raw)
    for (kp, a), b in zip(jax.tree_util.tree_flatten_with_path(target)[0], jax.tree.leaves(tree)):
        if np.shape(a) != np.shape(b):
            raise ValueError(f"{path}: {where}{jax.tree_util.keystr(kp)} has shape {np.shape(b)}, the model expects {np.shape(a)}")
    return tree


def manifest_path(path: str | os.PathLike) -> Path:
    return Path(str(path) + ".json")


def read_manifest(path: str | os.PathLike) -> dict:
    p = manifest_path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: weights manifest missing")
    return json.loads(p.read_text())

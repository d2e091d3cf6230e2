"""A dataset cached on disk: one .npz file per item plus manifest.json, written atomically, read back checked.

Layout (`NpzCacheFormat.write`): <prefix>_000000.npz ... (one per item, each written atomically)
and, written last, manifest.json with the format name and version, the package and numpy
versions, the generator's config, split, seed, count, the fields derived from the config (e.g.
point_features) and the file names. A rewrite deletes the manifest first, so a directory without
one was not finished. `NpzCachedDataset` checks the manifest before reading: a corrupt or mistyped
manifest or item file raises ValueError naming the file (and field), and the manifest's file names
must be relative paths inside the cache directory (data/paths.py). Loading needs no pickle.

What differs between the users (data/points/synthetic: point-cloud frames, data/rd/synthetic: RD
maps) is one `NpzCacheFormat` each: names, how an item becomes .npz bytes and back, the config type.
"""

from __future__ import annotations

import io
import json
import os
import tokenize
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .. import __version__
from ..core import atomic
from ..core.progress import generating
from .paths import inside
from .records import check_fields
from .splits import SPLITS, check_index

MANIFEST = "manifest.json"
MANIFEST_FIELDS = {"format": ("str", True), "config": ("object", True), "split": ("str", True),
                   "seed": ("count", True), "count": ("count", True)}  # then the derived fields, then "files"
# What a damaged .npz raises from zipfile / numpy.lib.format (SyntaxError, TokenError: a garbled
# .npy header dict), besides a missing array (KeyError); TypeError / AttributeError: a mistyped
# JSON entry inside it; MemoryError / OverflowError: a header that announces a huge array.
NPZ_ERRORS = (OSError, EOFError, ValueError, KeyError, SyntaxError, tokenize.TokenError, zipfile.BadZipFile,
              zlib.error, NotImplementedError, TypeError, AttributeError, MemoryError, OverflowError,
              RecursionError)
# What a config's from_dict raises on whatever JSON holds.
CONFIG_ERRORS = (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError)


@dataclass(frozen=True)
class NpzCacheFormat:
    """What one kind of cache stores and how it names things in its files and messages."""

    name: str  # the manifest's "format", e.g. "dsfec_jax.synthetic.frames"
    version: int  # the manifest's "format_version": the generator's FORMAT_VERSION
    prefix: str  # item files are f"{prefix}_{i:06d}.npz"
    noun: str  # "frame": "frame index 7 out of range", "2 frame files missing"
    item_title: str  # "RD sample": "not a cached RD sample"
    cache_title: str  # "an RD synthetic cache": "manifest.json not found: not an RD synthetic cache"
    encode: Callable[[Any], bytes]  # item -> .npz bytes
    decode: Callable[[Any], Any]  # open NpzFile -> item; one of NPZ_ERRORS when damaged
    config_type: type  # with to_dict() and from_dict(dict)
    config_title: str  # "an RDSyntheticConfig": "field 'config' is not an RDSyntheticConfig"
    # manifest fields that follow from the config, for readers that do not parse it:
    # field -> (data/records.py kind, config -> JSON value); checked against the config on reading
    derived: Mapping[str, tuple[str, Callable[[Any], Any]]] = field(default_factory=dict)

    def write(self, dataset, directory: str | os.PathLike) -> Path:
        """Writes every item of `dataset` (with cfg, split, seed, len, [i]) and then the manifest."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        (directory / MANIFEST).unlink(missing_ok=True)  # an unfinished rewrite must not look valid
        files = []
        for i in generating(range(len(dataset)), f"writing {len(dataset)} generated items to the cache {directory}",
                            unit="item"):
            name = f"{self.prefix}_{i:06d}.npz"
            atomic.write_bytes(directory / name, self.encode(dataset[i]))
            files.append(name)
        derived = {key: value(dataset.cfg) for key, (_, value) in self.derived.items()}
        atomic.write_json(directory / MANIFEST, dict(
            format=self.name, format_version=self.version, dsfec_jax_version=__version__,
            numpy_version=np.__version__, config=dataset.cfg.to_dict(), split=dataset.split, seed=dataset.seed,
            count=len(files), **derived, files=files))
        return directory

    def read_manifest(self, directory: str | os.PathLike) -> dict:
        """The checked manifest of a cache directory; ValueError naming manifest.json and the field."""
        path = Path(directory) / MANIFEST
        if not path.is_file():
            raise FileNotFoundError(f"{path} not found: not {self.cache_title}, or its writing did not finish")
        m = self._read_json(path)
        check_fields(m, {**MANIFEST_FIELDS, **{k: (kind, True) for k, (kind, _) in self.derived.items()},
                         "files": ("str_list", True)}, str(path))
        cfg = self.manifest_config(path, m["config"])
        if m["split"] not in SPLITS:
            raise ValueError(f"{path}: field 'split' = {m['split']!r}; expected one of {SPLITS}")
        for key, (_, value) in self.derived.items():
            if m[key] != value(cfg):
                raise ValueError(f"{path}: inconsistent manifest: field {key!r} = {m[key]!r}, "
                                 f"its config gives {value(cfg)!r}")
        if m["count"] != len(m["files"]):
            raise ValueError(f"{path}: field 'count' = {m['count']} but {len(m['files'])} files are listed")
        missing = [f for f in m["files"] if not inside(directory, f, path, "files").is_file()]
        if missing:
            raise ValueError(f"{path}: {len(missing)} {self.noun} files missing, e.g. {missing[0]}")
        return m

    def _read_json(self, path: Path) -> dict:
        """The manifest's JSON object, of this format and version; ValueError naming `path` otherwise."""
        try:
            m = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
            raise ValueError(f"{path}: not valid JSON ({type(e).__name__}: {e})") from None
        if not isinstance(m, dict) or m.get("format") != self.name or m.get("format_version") != self.version:
            have = (m.get("format"), m.get("format_version")) if isinstance(m, dict) else (type(m).__name__, None)
            raise ValueError(f"{path}: format {have[0]!r} v{have[1]}; this code reads {self.name!r} v{self.version}")
        return m

    def manifest_config(self, path: Path, config: dict):
        try:
            return self.config_type.from_dict(config)
        except CONFIG_ERRORS as e:  # from_dict takes whatever JSON holds
            raise ValueError(f"{path}: field 'config' is not {self.config_title} ({type(e).__name__}: {e})") from None

    def read_item(self, path: Path):
        try:
            with np.load(path, allow_pickle=False) as z:
                return self.decode(z)
        except NPZ_ERRORS as e:
            raise ValueError(f"{path}: not a cached {self.item_title} ({type(e).__name__}: {e})") from None


class NpzCachedDataset:
    """Items read back from a cache directory, optionally checked against a config, split and seed.

    A subclass names its `FORMAT`."""

    FORMAT: NpzCacheFormat

    def __init__(self, directory: str | os.PathLike, cfg=None, split: str | None = None, seed: int | None = None):
        self.directory = Path(directory)
        self.manifest = self.FORMAT.read_manifest(self.directory)
        self.cfg = self.FORMAT.manifest_config(self.directory / MANIFEST, self.manifest["config"])
        for key, want in dict(config=cfg, split=split, seed=seed).items():
            have = self.cfg if key == "config" else self.manifest[key]
            if want is not None and want != have:
                raise ValueError(f"cache {self.directory}: {key} is {have!r}, expected {want!r}; rebuild it")
        self.split, self.seed = self.manifest["split"], self.manifest["seed"]

    @classmethod
    def open(cls, directory: str | os.PathLike, dataset):
        """The cache at `directory` if it holds exactly `dataset` (config, split, seed, length), else
        (re)built from it first."""
        try:
            cached = cls(directory, dataset.cfg, dataset.split, dataset.seed)
            if len(cached) == len(dataset):
                return cached
        except (FileNotFoundError, ValueError):
            pass
        cls.FORMAT.write(dataset, directory)
        return cls(directory, dataset.cfg, dataset.split, dataset.seed)

    def __len__(self) -> int:
        return self.manifest["count"]

    def __getitem__(self, index: int):
        index = check_index(index, len(self), self.FORMAT.noun)
        return self.FORMAT.read_item(self.directory / self.manifest["files"][index])

    def __iter__(self):
        return (self[i] for i in range(len(self)))


# ------------------------------------------------------------------------- item files


def npz_bytes(arrays: dict[str, np.ndarray], meta: dict) -> bytes:
    """`arrays` and `meta` as .npz bytes: array-valued meta entries as `meta.<key>`, the others
    as JSON in `meta_json` (no pickle)."""
    arrays, plain = dict(arrays), {}
    for key, value in meta.items():
        if isinstance(value, np.ndarray):
            arrays[f"meta.{key}"] = value
        else:
            plain[key] = value
    arrays["meta_json"] = np.array(json.dumps(plain))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def npz_meta(z) -> dict:
    """The meta of `npz_bytes` (JSON lists stay lists); ValueError when meta_json is not an object."""
    meta = json.loads(str(z["meta_json"]))
    if not isinstance(meta, dict):
        raise ValueError("meta_json must hold a JSON object")
    meta.update({k[5:]: z[k] for k in z.files if k.startswith("meta.")})
    return meta

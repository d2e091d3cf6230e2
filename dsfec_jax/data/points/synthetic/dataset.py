"""Splits, determinism and the on-disk cache.

Frame i of split s with seed k is drawn from np.random.default_rng(SeedSequence((k, s_id, i))):
a pure function of (config, split, index, seed), the same on every machine, and the three
splits draw from disjoint streams. Nothing is stored: `SyntheticDataset` generates on access.

Cache format (`write_cache`): a directory of frame_000000.npz ... (one per frame, written
atomically) and, written last, manifest.json with the format name and version, the package and
numpy versions, the config, split, seed, count, point features and file names. A directory
whose manifest is missing was not finished. `CachedDataset` checks the manifest before reading:
a corrupt or mistyped manifest or frame file raises ValueError naming the file (and field), and
the manifest's file names must be relative paths inside the cache directory.
Each .npz holds points (N, F) float32, point_features, box_center/size/yaw/velocity/names,
frame_id, array-valued meta entries as `meta.<key>`, and the other meta entries as JSON in
`meta_json`. Loading needs no pickle.
"""

from __future__ import annotations

import io
import json
import os
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .... import __version__
from ....core import atomic
from ....core.atomic import write_json
from ..frame import Boxes, Frame
from ...paths import inside
from ...records import check_fields
from .config import FORMAT_VERSION, SyntheticConfig
from .simulate import simulate

SPLITS = ("train", "val", "test")
CACHE_FORMAT = "dsfec_jax.synthetic.frames"
MANIFEST = "manifest.json"
MANIFEST_FIELDS = {"format": ("str", True), "config": ("object", True), "split": ("str", True),
                   "seed": ("count", True), "count": ("count", True), "point_features": ("str_list", True),
                   "files": ("str_list", True)}
# What a damaged .npz raises from zipfile / numpy.lib.format (SyntaxError, TokenError: a garbled
# .npy header dict), besides a missing array (KeyError).
NPZ_ERRORS = (OSError, EOFError, ValueError, KeyError, SyntaxError, tokenize.TokenError, zipfile.BadZipFile,
              zlib.error, NotImplementedError)


def frame_rng(seed: int, split: str, index: int) -> np.random.Generator:
    if split not in SPLITS:
        raise ValueError(f"split={split!r}; expected one of {SPLITS}")
    if seed < 0 or index < 0:
        raise ValueError(f"seed={seed} and index={index} must be >= 0")
    return np.random.default_rng(np.random.SeedSequence((int(seed), SPLITS.index(split), int(index))))


def generate_frame(cfg: SyntheticConfig, split: str, index: int, seed: int = 0) -> Frame:
    meta = dict(split=split, index=int(index), seed=int(seed))
    return simulate(frame_rng(seed, split, index), cfg, f"synthetic-{split}-s{seed}-{index:06d}", meta)


class SyntheticDataset:
    """`num_frames` frames of one split, generated on access (random access, no state)."""

    def __init__(self, cfg: SyntheticConfig | None = None, split: str = "train", seed: int = 0,
                 num_frames: int = 1000):
        if split not in SPLITS:
            raise ValueError(f"split={split!r}; expected one of {SPLITS}")
        self.cfg, self.split, self.seed, self.num_frames = cfg or SyntheticConfig(), split, int(seed), int(num_frames)

    def __len__(self) -> int:
        return self.num_frames

    def __getitem__(self, index: int) -> Frame:
        index = _check_index(index, self.num_frames)
        return generate_frame(self.cfg, self.split, index, self.seed)

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def __repr__(self):
        return f"SyntheticDataset({self.split!r}, seed={self.seed}, num_frames={self.num_frames}, {self.cfg.difficulty!r})"


def _check_index(index: int, n: int) -> int:
    index = int(index)
    if index < 0:
        index += n
    if not 0 <= index < n:
        raise IndexError(f"frame index {index} out of range for {n} frames")
    return index


# ------------------------------------------------------------------------------------- cache


def write_cache(dataset: SyntheticDataset, directory: str | os.PathLike) -> Path:
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    (directory / MANIFEST).unlink(missing_ok=True)  # an unfinished rewrite must not look valid
    files = []
    for i in range(len(dataset)):
        name = f"frame_{i:06d}.npz"
        atomic.write_bytes(directory / name, frame_to_npz_bytes(dataset[i]))
        files.append(name)
    write_json(directory / MANIFEST, dict(
        format=CACHE_FORMAT, format_version=FORMAT_VERSION, dsfec_jax_version=__version__,
        numpy_version=np.__version__, config=dataset.cfg.to_dict(), split=dataset.split, seed=dataset.seed,
        count=len(files), point_features=list(dataset.cfg.point_features), files=files))
    return directory


class CachedDataset:
    """Frames read back from a `write_cache` directory; optionally checked against a config."""

    def __init__(self, directory: str | os.PathLike, cfg: SyntheticConfig | None = None,
                 split: str | None = None, seed: int | None = None):
        self.directory = Path(directory)
        self.manifest = read_manifest(self.directory)
        self.cfg = SyntheticConfig.from_dict(self.manifest["config"])
        expected = dict(config=cfg, split=split, seed=seed)
        for key, want in expected.items():
            have = self.cfg if key == "config" else self.manifest[key]
            if want is not None and want != have:
                raise ValueError(f"cache {self.directory}: {key} is {have!r}, expected {want!r}; rebuild it")
        self.split, self.seed = self.manifest["split"], self.manifest["seed"]

    def __len__(self) -> int:
        return self.manifest["count"]

    def __getitem__(self, index: int) -> Frame:
        index = _check_index(index, len(self))
        path = self.directory / self.manifest["files"][index]
        try:
            with np.load(path, allow_pickle=False) as z:
                return frame_from_npz(z)
        except NPZ_ERRORS as e:
            raise ValueError(f"{path}: not a cached frame ({type(e).__name__}: {e})") from None

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def read_manifest(directory: Path) -> dict:
    """The checked manifest of a cache directory; ValueError naming manifest.json and the field."""
    path = Path(directory) / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: not a synthetic cache, or its writing did not finish")
    try:
        m = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
        raise ValueError(f"{path}: not valid JSON ({type(e).__name__}: {e})") from None
    if not isinstance(m, dict) or m.get("format") != CACHE_FORMAT or m.get("format_version") != FORMAT_VERSION:
        have = (m.get("format"), m.get("format_version")) if isinstance(m, dict) else (type(m).__name__, None)
        raise ValueError(f"{path}: format {have[0]!r} v{have[1]}; this code reads {CACHE_FORMAT!r} v{FORMAT_VERSION}")
    check_fields(m, MANIFEST_FIELDS, str(path))
    features = _manifest_config(path, m["config"]).point_features
    if m["split"] not in SPLITS:
        raise ValueError(f"{path}: field 'split' = {m['split']!r}; expected one of {SPLITS}")
    if tuple(m["point_features"]) != features or m["count"] != len(m["files"]):
        raise ValueError(f"{path}: inconsistent manifest (features {m['point_features']}, "
                         f"count {m['count']} for {len(m['files'])} files)")
    missing = [f for f in m["files"] if not inside(directory, f, path, "files").is_file()]
    if missing:
        raise ValueError(f"{path}: {len(missing)} frame files missing, e.g. {missing[0]}")
    return m


def _manifest_config(path: Path, config: dict) -> SyntheticConfig:
    try:
        return SyntheticConfig.from_dict(config)
    except (KeyError, TypeError, ValueError, AttributeError) as e:  # from_dict takes whatever JSON holds
        raise ValueError(f"{path}: field 'config' is not a SyntheticConfig ({type(e).__name__}: {e})") from None


def open_cache(directory, cfg: SyntheticConfig, split: str, seed: int, num_frames: int) -> CachedDataset:
    """The cache at `directory` if it holds exactly this dataset, else (re)build it first."""
    try:
        cached = CachedDataset(directory, cfg, split, seed)
        if len(cached) == num_frames:
            return cached
    except (FileNotFoundError, ValueError):
        pass
    write_cache(SyntheticDataset(cfg, split, seed, num_frames), directory)
    return CachedDataset(directory, cfg, split, seed)


def frame_to_npz_bytes(frame: Frame) -> bytes:
    b = frame.boxes
    arrays = dict(points=frame.points, point_features=np.array(frame.point_features), frame_id=np.array(frame.frame_id),
                  source=np.array(frame.source), box_center=b.center, box_size=b.size, box_yaw=b.yaw,
                  box_velocity=b.velocity, box_names=b.names.astype("<U16"))
    plain = {}
    for key, value in frame.meta.items():
        if isinstance(value, np.ndarray):
            arrays[f"meta.{key}"] = value
        else:
            plain[key] = list(value) if isinstance(value, tuple) else value
    arrays["meta_json"] = np.array(json.dumps(plain))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def frame_from_npz(z) -> Frame:
    """The frame of `frame_to_npz_bytes`; ValueError (or KeyError for a missing array) when damaged."""
    meta = json.loads(str(z["meta_json"]))
    if not isinstance(meta, dict) or z["point_features"].ndim != 1:
        raise ValueError("meta_json must hold a JSON object and point_features a 1-D array of names")
    meta = {k: tuple(v) if isinstance(v, list) else v for k, v in meta.items()}
    meta.update({k[5:]: z[k] for k in z.files if k.startswith("meta.")})
    boxes = Boxes(z["box_center"], z["box_size"], z["box_yaw"], z["box_velocity"], z["box_names"])
    return Frame(z["points"], tuple(str(f) for f in z["point_features"]), boxes, str(z["frame_id"]),
                 str(z["source"]), meta)

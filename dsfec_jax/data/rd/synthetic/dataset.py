"""Splits, determinism and the on-disk cache of the RD simulator (as data/points/synthetic/dataset.py).

Samples follow data/splits.py: sample i of split s with seed k is a pure function of (config,
split, index, seed). `RDSyntheticDataset` generates on access.

Cache (`write_cache`, data/npz_cache.py): rd_000000.npz ... and, written last, manifest.json
(format "dsfec_jax.rd_synthetic.samples"); `RDCachedDataset` checks it before reading. Each .npz
holds power (R, D) float32, range_m, velocity_mps, box_xyxy, box_names, scale, sample_id, source,
the sensor as JSON, array meta entries as `meta.<key>` and the other meta entries as JSON in
`meta_json`.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from ....boxes.boxes2d import Boxes2D
from ...npz_cache import NpzCachedDataset, NpzCacheFormat, npz_bytes, npz_meta
from ...splits import SPLITS, check_index, check_split, split_rng  # noqa: F401 (SPLITS: exported here)
from ..sample import RDAxes, RDSample
from ..sensor import FMCWSensor
from .config import FORMAT_VERSION, RDSyntheticConfig, benchmark_config
from .simulate import simulate

sample_rng = split_rng  # the random stream of one sample: sample_rng(seed, split, index)


def generate_sample(cfg: RDSyntheticConfig, split: str, index: int, seed: int = 0) -> RDSample:
    meta = dict(split=split, index=int(index), seed=int(seed))
    return simulate(sample_rng(seed, split, index), cfg, f"rd-synthetic-{split}-s{seed}-{index:06d}", meta)


class RDSyntheticDataset:
    """`num_samples` samples of one split, generated on access (random access, no state)."""

    def __init__(self, cfg: RDSyntheticConfig | None = None, split: str = "train", seed: int = 0,
                 num_samples: int = 1000):
        self.cfg, self.split = cfg or benchmark_config(), check_split(split)
        self.seed, self.num_samples = int(seed), int(num_samples)

    def __len__(self) -> int:
        return self.num_samples

    def __getitem__(self, index: int) -> RDSample:
        return generate_sample(self.cfg, self.split, check_index(index, self.num_samples, "sample"), self.seed)

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def __repr__(self):
        return f"RDSyntheticDataset({self.split!r}, seed={self.seed}, num_samples={self.num_samples})"


# ------------------------------------------------------------------------------------- cache


def sample_to_npz_bytes(sample: RDSample) -> bytes:
    b = sample.boxes
    sensor = None if sample.sensor is None else dataclasses.asdict(sample.sensor)
    return npz_bytes(dict(power=np.asarray(sample.power, np.float32), range_m=sample.axes.range_m,
                          velocity_mps=sample.axes.velocity_mps, box_xyxy=np.asarray(b.xyxy, np.float32),
                          box_names=np.asarray(b.names).astype("<U16"), scale=np.array(sample.scale),
                          sample_id=np.array(sample.sample_id), source=np.array(sample.source),
                          sensor_json=np.array(json.dumps(sensor))), sample.meta)


def sample_from_npz(z) -> RDSample:
    """The sample of `sample_to_npz_bytes`; ValueError (or KeyError for a missing array) when damaged."""
    meta = npz_meta(z)
    sensor = json.loads(str(z["sensor_json"]))
    if not (sensor is None or isinstance(sensor, dict)):
        raise ValueError("sensor_json must hold a JSON object or null")
    xyxy, names = z["box_xyxy"], z["box_names"]
    if xyxy.dtype.kind != "f" or names.dtype.kind != "U" or z["power"].dtype != np.float32:
        raise ValueError(f"box_xyxy must be float, box_names text and power float32; got {xyxy.dtype}, "
                         f"{names.dtype}, {z['power'].dtype}")
    return RDSample(z["power"], RDAxes(z["range_m"], z["velocity_mps"]), Boxes2D(xyxy, names),
                    None if sensor is None else FMCWSensor(**sensor), str(z["scale"]), sample_id=str(z["sample_id"]),
                    source=str(z["source"]), meta=meta)


SAMPLES = NpzCacheFormat(
    name="dsfec_jax.rd_synthetic.samples", version=FORMAT_VERSION, prefix="rd", noun="sample",
    item_title="RD sample", cache_title="an RD synthetic cache", encode=sample_to_npz_bytes,
    decode=sample_from_npz, config_type=RDSyntheticConfig, config_title="an RDSyntheticConfig")


class RDCachedDataset(NpzCachedDataset):
    """Samples read back from a `write_cache` directory; optionally checked against a config, split, seed."""

    FORMAT = SAMPLES


write_cache = SAMPLES.write  # (dataset, directory) -> directory: the samples, then manifest.json
read_manifest = SAMPLES.read_manifest  # (directory) -> the checked manifest; ValueError naming file and field


def open_cache(directory, cfg: RDSyntheticConfig, split: str, seed: int, num_samples: int) -> RDCachedDataset:
    """The cache at `directory` if it holds exactly this dataset, else (re)build it first."""
    return RDCachedDataset.open(directory, RDSyntheticDataset(cfg, split, seed, num_samples))

"""Named RD sources -> lists of RDSample, what training, evaluation and the commands read.

`synthetic` (or `rd-synthetic`: the embedded FMCW benchmark, generated; splits train/val/test;
`synthetic:v1` is the benchmark before issue 54's realism, which the records of that time were
made on; `synthetic:v2`, what plain `synthetic` means (config.DEFAULT_BENCHMARK) and what the
shipped RD weights are trained on, adds static clutter, the IF chain's shape and the Tx->Rx coupling),
`raddet:PATH` (a RADDet root holding train/ and test/ split folders, or one split folder) and
`carrada:PATH` (a CARRADA root with its sequence split file). Samples are materialised once:
a training run visits each many times, and re-simulating a map per visit would cost the host the
simulator's time again for nothing (its rate: docs/range-doppler.md; `python -m dsfec_jax.data
inspect --source rd-synthetic` prints it).
"""

from __future__ import annotations

from pathlib import Path

from ...core.progress import generating
from .sample import RDSample

SOURCE_KINDS = ("synthetic[:vN]", "rd-synthetic[:vN]", "raddet:PATH", "carrada:PATH")
SYNTHETIC_SAMPLES = 200  # `synthetic` without a count


class NoSamples(ValueError):
    """A source, split or count that yields no samples: scoring or training on nothing is refused."""


def load_rd_samples(data: str, split: str, count: int | None = None, seed: int = 0) -> list[RDSample]:
    """The first `count` samples of `split` of the source `data` (synthetic: `count` generated
    samples, default SYNTHETIC_SAMPLES; real sources: default all of the split)."""
    if count is not None and count < 1:
        raise NoSamples(f"count={count}: expected a positive number of samples (or None for the source's default)")
    kind, _, path = data.partition(":")
    if kind in ("synthetic", "rd-synthetic"):
        from .synthetic import SPLITS, RDSyntheticDataset
        if split not in SPLITS:
            raise NoSamples(f"--data {data}: splits are {SPLITS}, not {split!r}")
        dataset = RDSyntheticDataset(synthetic_config(data, path), split=split, seed=seed,
                                     num_samples=count or SYNTHETIC_SAMPLES)
        return list(generating(dataset, f"generating {len(dataset)} synthetic RD maps ({split})", unit="map"))
    if kind not in ("raddet", "carrada"):
        raise ValueError(f"--data {data!r}: expected one of {', '.join(SOURCE_KINDS)}")
    if not path or not Path(path).exists():
        raise FileNotFoundError(f"--data {data}: expected {kind}:PATH with an existing path")
    dataset = _real(kind, Path(path), split)
    samples = [dataset[i] for i in range(len(dataset) if count is None else min(count, len(dataset)))]
    if not samples:
        raise NoSamples(f"--data {data}: split {split!r} holds no samples")
    return samples


def synthetic_config(data: str, version: str):
    """The benchmark config of `synthetic[:vN]` ("" for DEFAULT_BENCHMARK: the shipped weights' benchmark)."""
    from .synthetic.config import BENCHMARK_VERSIONS, DEFAULT_BENCHMARK, benchmark_config
    known = [f"v{v}" for v in BENCHMARK_VERSIONS]
    if version and version not in known:
        raise ValueError(f"--data {data!r}: the synthetic benchmark versions are {known}")
    return benchmark_config(int(version[1:]) if version else DEFAULT_BENCHMARK)


def _real(kind: str, path: Path, split: str):
    if kind == "raddet":
        from .raddet import RADDetDataset
        # a root with split folders, or a split folder itself (RADDet ships train/ and test/)
        return RADDetDataset(path, split if (path / split).is_dir() else None)
    from .carrada import CarradaDataset
    return CarradaDataset(path, split)

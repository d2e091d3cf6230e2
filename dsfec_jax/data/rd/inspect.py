"""What is in an RD source: the statistics of data/rd/stats.py, how fast it was made or read, the
strongest moving target of an unlabelled capture, and PNG previews of both input representations.

Sources: 'rd-synthetic' (the FMCW simulator; target = split; `benchmark` picks its version),
'ti-adc' (a raw TI capture: a file, or a directory holding one), 'raddet' (a RADDet split
directory), 'carrada' (a CARRADA root).

The statistics and the map structure (stats.structure_stats: ridge, floor shape, peak) are also
given per channel count, since a sum over 8 channels has a tighter floor than one channel's map:
the TI directory holds a 1-channel and an 8-channel file, which those columns never pool.
`versus` ("SOURCE[:PATH]") adds another source's columns beside them, like for like.
"""

from __future__ import annotations

import time
from pathlib import Path

from ...core.atomic import write_json
from ...core.provenance import versions
from .preview import save_rd_png
from .sample import RDSample
from .stats import dataset_stats, structure_summary

RD_SOURCES = ("rd-synthetic", "ti-adc", "raddet", "carrada")


def load_rd(source: str, target: str, split: str | None = None, count: int = 50, seed: int = 0,
            benchmark: int | None = None) -> tuple[list[RDSample], dict]:
    """Up to `count` samples of a source, and facts about how they were obtained."""
    if source == "rd-synthetic":
        from .synthetic import generate_sample
        from .synthetic.config import DEFAULT_BENCHMARK, benchmark_config
        version = DEFAULT_BENCHMARK if benchmark is None else benchmark
        cfg, split = benchmark_config(version), split or "val"
        start = time.perf_counter()  # the samples inspected are the ones timed: no second pass
        samples = [generate_sample(cfg, split, i, seed) for i in range(count)]
        rate = count / (time.perf_counter() - start)
        return samples, {"split": split, "seed": seed, "benchmark": version, "maps_per_s": round(rate, 1),
                         "sensor": cfg.sensor.describe()}
    path = Path(target)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or directory for source {source!r}")
    if source == "ti-adc":
        from .ti_adc import load_ti_sample, strongest_moving_target
        names = [path.name] if path.is_file() else ["simple_frame_1.npy", "doppler_example_1.npy"]
        samples = [load_ti_sample(path.parent if path.is_file() else path, n) for n in names]
        # 2: skip the zero-Doppler column and its neighbours, where the Hann window spreads static returns
        return samples, {"targets": {s.sample_id: strongest_moving_target(s, 2) for s in samples},
                         "sensor": samples[0].sensor.describe()}
    if source == "raddet":
        from .raddet import RADDetDataset
        data = RADDetDataset(path, split)
    elif source == "carrada":
        from .carrada import CarradaDataset
        data = CarradaDataset(path, split)
    else:
        raise ValueError(f"unknown RD source {source!r}; valid: {RD_SOURCES}")
    samples = [data[i] for i in range(min(count, len(data)))]
    return samples, {"samples_in_source": len(data)}


def by_channels(name: str, samples: list[RDSample]) -> dict[str, list[RDSample]]:
    """{'NAME Cch': its samples} for each channel count among the samples (unknown: '?ch'), sorted."""
    groups: dict[str, list[RDSample]] = {}
    for s in samples:
        groups.setdefault(f"{name} {s.sensor.num_channels if s.sensor else '?'}ch", []).append(s)
    return dict(sorted(groups.items()))


def parse_versus(versus: str) -> tuple[str, str]:
    """'SOURCE[:PATH]' -> (source, path); a real source needs its path."""
    source, _, path = versus.partition(":")
    if source not in RD_SOURCES:
        raise ValueError(f"--versus {versus!r}: the source must be one of {RD_SOURCES}")
    if source != "rd-synthetic" and not path:
        raise ValueError(f"--versus {versus!r}: {source} needs SOURCE:PATH")
    return source, path


def inspect_rd(source: str, target: str, split: str | None = None, count: int = 50, seed: int = 0,
               png_dir: str | None = None, previews: int = 3, colormap: str = "viridis",
               command: str = "", benchmark: int | None = None, versus: str | None = None) -> dict:
    """Statistics of a source (and the map structure of `versus` beside it); with `png_dir`, PNG
    previews plus previews.json recording what made them (the command, source, split, seed,
    versions), as every shipped picture must."""
    samples, info = load_rd(source, target, split, count, seed, benchmark)
    groups = by_channels(source, samples)
    if versus:
        other, path = parse_versus(versus)
        groups |= by_channels(other, load_rd(other, path, None, count, seed)[0])
    summary = {"source": source, "stats": dataset_stats(samples),
               "stats_by_channels": {label: dataset_stats(group) for label, group in groups.items()},
               "structure": {label: structure_summary(group) for label, group in groups.items()}, "info": info}
    if png_dir:
        files = [save_rd_png(s, Path(png_dir) / f"{_file_name(s)}.png", colormap) for s in samples[:previews]]
        summary["previews"] = [str(f) for f in files]
        write_json(Path(png_dir) / "previews.json", {
            "command": command, "source": source, "target": target, "split": split, "seed": seed,
            "colormap": colormap, "files": [f.name for f in files], "versions": versions(("numpy", "dsfec_jax"))})
    return summary


def _file_name(sample: RDSample) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in sample.sample_id) or "sample"

"""What an input modality is, as one record: shared code (the CLI, the search, the benchmarks)
asks the modality of a config for its verbs, and never compares modality names.

A modality lives in its own folder (`modalities/<name>/`: predict, evaluate, fit, export, ort,
quantize, bench, train_bench, cli and `record.py` with its `MODALITY`); `registry.MODALITIES`
lists the records. Families name their modality (`Family.modality`); the registry maps that name
to this record.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable, Mapping


@dataclasses.dataclass(frozen=True)
class Protocol:
    """How detections are scored. `validate(predictor, samples, match_classes)` -> (logged scores,
    per-sample match tables for bootstrap intervals, {} where none are kept); `report(samples,
    detections, predictor)` -> (the eval command's fields, its one-line summary)."""

    validate: Callable[..., tuple[dict, dict]]
    report: Callable[..., tuple[dict, str]]


@dataclasses.dataclass(frozen=True)
class Commands:
    """The `dsfec` verbs as this modality runs them; each gets the parsed arguments and the config
    the CLI resolved once from --model and --set. `train(args, cfg, schedule, info)`,
    `eval_or_predict(args, cfg)`, `export(args, cfg, command)` and `quantize(args)` return an exit
    code; `ship_predictor(cfg, source, info)` -> (predictor, variables) measured for a manifest.
    `data_fields(args, overrides)` adds the config fields the data decides (the camera family's
    classes) before the config is resolved; `refuse(args, command)` exits naming a flag this
    modality does not take."""

    train: Callable[..., int]
    eval_or_predict: Callable[..., int]
    ship_predictor: Callable[..., tuple[Any, dict]]
    export: Callable[..., int]
    quantize: Callable[..., int]
    data_fields: Callable[[Any, dict], dict]
    refuse: Callable[[Any, str], None]


@dataclasses.dataclass(frozen=True)
class ZooTable:
    """Where the zoo table of this modality's models lives: README `markers` (start, end), the
    `record` file it is generated from, `rows(records)` -> markdown rows and the footer `note`."""

    markers: tuple[str, str]
    record: Path
    rows: Callable[[list], str]
    note: str


@dataclasses.dataclass(frozen=True)
class Modality:
    """Everything that differs between kinds of input.

    `name` is what a Family's `modality` field holds ('points', 'rd', 'image'); `noun` what one
    sample is called in messages (frame, sample, image).
    Data: `load_samples(family, source, split, count, seed)` -> samples of a source (the family's
    benchmark when `source` is its name).
    Inference: `predictor(detector, variables, **options)` -> a callable predictor (JAX);
    `ort_predictor(export_dir, **options)` the same over an ONNX export.
    Scoring: `protocols` (metric name -> Protocol): the names a Family's MetricProtocol may hold.
    Deploy: `export(detector, variables, out_dir, **options)`; `quantize(export_dir, out_dir,
    samples, **options)`; `bench_chains(name, runtimes, threads, workdir, repeats)` -> runtime ->
    (chain of (stage, fn) from raw input to boxes, record fields) (deploy.bench times them).
    Profiling (profile/ asks these; it never imports this room): `stage_name(module path)` -> the
    stage a parameter or layer counts in; `latency_stages(detector, variables, inputs)` -> {stage:
    jitted zero-argument callable}; `size_fields(variables)` -> the record's extra size fields;
    `train_bench_fields(name, settings)` -> the config fields the train bench sets and
    `train_bench_batches(name, overrides, settings)` -> (detector, device batches, windows)
    (profile.training); `train_bench_note(records, settings)` -> what the train-bench table's footer
    says of this modality's records ('' for none); `zoo_table` (the README zoo table).
    Commands: `commands` (the CLI's verbs)."""

    name: str
    noun: str
    load_samples: Callable[..., Any]
    predictor: Callable[..., Any]
    ort_predictor: Callable[..., Any]
    protocols: Mapping[str, Protocol]
    commands: Commands
    export: Callable[..., Any]
    quantize: Callable[..., Any]
    bench_chains: Callable[..., dict]
    stage_name: Callable[[tuple], str]
    latency_stages: Callable[..., dict]
    size_fields: Callable[[dict], dict]
    train_bench_fields: Callable[..., dict]
    train_bench_batches: Callable[..., tuple]
    train_bench_note: Callable[[list, dict], str]
    zoo_table: ZooTable

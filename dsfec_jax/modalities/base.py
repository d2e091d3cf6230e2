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

from .files import FileReader

ALL_CLASSES = "*"  # among a Protocol's match_classes: every class of the predictor


@dataclasses.dataclass(frozen=True)
class Protocol:
    """How detections are scored. `validate(predictor, samples, match_classes)` predicts and scores
    -> (logged scores, per-sample match tables of `match_classes` for bootstrap intervals, {} where
    none are kept; ALL_CLASSES asks for every class); `report(samples, detections, predictor)` ->
    (the eval command's fields, its one-line summary)."""

    validate: Callable[..., tuple[dict, dict]]
    report: Callable[..., tuple[dict, str]]


@dataclasses.dataclass(frozen=True)
class Commands:
    """The `dsfec` verbs as this modality runs them (modalities/<name>/cli.py). cli.py parses the
    flags, asks `refuse`, resolves the config once (--model, --set and `config_fields`) and hands
    each verb the parsed arguments and that config; it prints what the verbs return.

    `refuse(args, command)` exits naming a flag this modality does not take (given explicitly).
    `config_fields(args, overrides)` -> the overrides the config is resolved with: --set plus the
    fields the flags or the data decide (points: --max-pillars; image: the classes of --data for
    train, of the run that made --weights otherwise).
    `train(args, cfg, overrides, schedule, info)` -> the final validation scores (run.json records
    `overrides`, `info` the command and data).
    `eval_or_predict(args, cfg)` -> (items, detections, predictor, extra report fields) after
    writing predict's files; the CLI scores and prints them with the family's protocol.
    `ship_predictor(cfg, source, info)` -> (predictor, variables) of a run's checkpoint at the
    evaluation settings, `cfg` the run's config (run.json's overrides).
    `export(args, cfg, command)` and `quantize(args)` -> the written files and figures."""

    refuse: Callable[[Any, str], None]
    config_fields: Callable[[Any, dict], dict]
    train: Callable[..., dict]
    eval_or_predict: Callable[..., tuple]
    ship_predictor: Callable[..., tuple[Any, dict]]
    export: Callable[..., dict]
    quantize: Callable[..., dict]


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
    benchmark when `source` is its name); `files` reads a user's own files (`dsfec predict --input`,
    `api.read_files`: modalities/files.py).
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
    Training: `fit(cfg, samples, val, schedule, run_dir, seed, steps, augment, eval_every, run_info,
    progress, init_variables, *, overrides, match_classes, **options)` -> (detector, final state,
    validation scores); `options` are the modality's own (points: window, window_sampling).
    Commands: `commands` (the CLI's verbs)."""

    name: str
    noun: str
    load_samples: Callable[..., Any]
    predictor: Callable[..., Any]
    ort_predictor: Callable[..., Any]
    protocols: Mapping[str, Protocol]
    fit: Callable[..., tuple]
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
    files: FileReader

"""The point-cloud modality (DSFEC, RadarNeXt): pillarized radar points, BEV boxes, nuScenes and
VoD protocols."""

from __future__ import annotations

from ..base import Commands, Modality
from . import cli
from .evaluate import PROTOCOLS
from .fit import fit
from .zoo_table import TABLE as ZOO_TABLE


def load_samples(family, source: str, split: str, count: int | None, seed: int):
    from ...data.points.sources import load_frames
    return load_frames(source, split, count, seed, features=family.points.input_columns)


def predictor(detector, variables, **options):
    from .predict import predictor_for
    return predictor_for(detector, variables, **options)


def ort_predictor(export_dir, **options):
    from .ort import OrtPredictor
    return OrtPredictor(export_dir, **options)


def export(detector, variables, out_dir, **options):
    from .export import export as export_points
    return export_points(detector, variables, out_dir, **options)


def quantize(export_dir, out_dir, samples, **options):
    from .quantize import quantize as quantize_points
    return quantize_points(export_dir, out_dir, samples, **options)


def bench_chains(name, runtimes, threads, workdir, repeats):
    from .bench import point_chains
    return point_chains(name, runtimes, threads, workdir, repeats)


def stage_name(path):
    from .profile import stage_of
    return stage_of(path)


def latency_stages(detector, variables, inputs):
    from .profile import latency_stages as stages
    return stages(detector, variables, inputs)


def size_fields(variables):
    return {}


def train_bench_fields(name, settings):
    from .train_bench import fields
    return fields(name, settings)


def train_bench_batches(name, overrides, settings):
    from .train_bench import training_batches
    return training_batches(name, overrides, settings)


def train_bench_note(records, settings):
    from .train_bench import note
    return note(records, settings)


MODALITY = Modality(
    name="points", noun="frame", load_samples=load_samples, predictor=predictor, ort_predictor=ort_predictor,
    protocols=PROTOCOLS, fit=fit,
    commands=Commands(refuse=cli.refuse, config_fields=cli.config_fields, train=cli.train,
                      eval_or_predict=cli.eval_or_predict, ship_predictor=cli.ship_predictor, export=cli.export,
                      quantize=cli.quantize),
    export=export, quantize=quantize, bench_chains=bench_chains, stage_name=stage_name,
    latency_stages=latency_stages, size_fields=size_fields, train_bench_fields=train_bench_fields,
    train_bench_batches=train_bench_batches, train_bench_note=train_bench_note, zoo_table=ZOO_TABLE,
)

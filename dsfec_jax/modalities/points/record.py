"""The point-cloud modality (DSFEC, RadarNeXt): pillarized radar points, BEV boxes, nuScenes and
VoD protocols."""

from __future__ import annotations

from ...data.points.sources import load_frames
from ..base import Commands, Modality
from . import cli
from .bench import point_chains
from .evaluate import PROTOCOLS
from .export import export
from .files import READER as FILES
from .fit import fit
from .ort import OrtPredictor
from .predict import predictor_for
from .profile import latency_stages, stage_of
from .quantize import quantize
from .train_bench import fields, note, training_batches
from .zoo_table import TABLE as ZOO_TABLE


def load_samples(family, source: str, split: str, count: int | None, seed: int):
    """Frames of `source` mapped onto the family's input columns."""
    return load_frames(source, split, count, seed, features=family.points.input_columns)


MODALITY = Modality(
    name="points", noun="frame", load_samples=load_samples, predictor=predictor_for, ort_predictor=OrtPredictor,
    protocols=PROTOCOLS, fit=fit,
    commands=Commands(refuse=cli.refuse, config_fields=cli.config_fields, train=cli.train,
                      eval_or_predict=cli.eval_or_predict, ship_predictor=cli.ship_predictor, export=cli.export,
                      quantize=cli.quantize),
    export=export, quantize=quantize, bench_chains=point_chains, stage_name=stage_of,
    latency_stages=latency_stages, size_fields=lambda variables: {}, train_bench_fields=fields,
    train_bench_batches=training_batches, train_bench_note=note, zoo_table=ZOO_TABLE, files=FILES,
)

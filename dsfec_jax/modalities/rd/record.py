"""The range-Doppler modality (the YOLO-RD family): RD maps as images, 2D boxes in map cells, COCO AP."""

from __future__ import annotations

from ...data.rd.sources import load_rd_samples
from ...profile.counting import part_of
from ..base import Commands, Modality
from . import cli
from .bench import rd_chains
from .evaluate import PROTOCOLS
from .export import export_rd
from .files import READER as FILES
from .fit import fit_rd
from .ort import OrtRDPredictor
from .predict import RDPredictor
from .profile import latency_stages, size_fields
from .quantize import quantize_rd
from .train_bench import note, training_batches
from .zoo_table import TABLE as ZOO_TABLE

MODALITY = Modality(
    name="rd", noun="sample", load_samples=lambda family, *where: load_rd_samples(*where),
    predictor=RDPredictor, ort_predictor=OrtRDPredictor, protocols=PROTOCOLS, fit=fit_rd,
    commands=Commands(refuse=cli.refuse, config_fields=cli.config_fields, train=cli.train,
                      eval_or_predict=cli.eval_or_predict, ship_predictor=cli.ship_predictor, export=cli.export,
                      quantize=cli.quantize),
    export=export_rd, quantize=quantize_rd, bench_chains=rd_chains, stage_name=part_of,
    latency_stages=latency_stages, size_fields=size_fields, train_bench_fields=lambda name, settings: {},
    train_bench_batches=training_batches, train_bench_note=note, zoo_table=ZOO_TABLE, files=FILES,
)

"""The camera-image modality (Shuffle-YOLOv3, YOLOv3): RGB images, 2D boxes in pixels, VOC07 AP."""

from __future__ import annotations

from ..base import Commands, Modality
from . import cli
from .evaluate import PROTOCOLS
from .fit import fit_camera
from .zoo_table import TABLE as ZOO_TABLE


def load_samples(family, source: str, split: str, count: int | None, seed: int):
    from ...data.camera.sources import load_camera_images
    return load_camera_images(source, split, count, seed)


def predictor(detector, variables, **options):
    from .predict import CameraPredictor
    return CameraPredictor(detector, variables, **options)


def ort_predictor(export_dir, **options):
    from .ort import OrtCameraPredictor
    return OrtCameraPredictor(export_dir, **options)


def export(detector, variables, out_dir, **options):
    from .export import export_camera
    return export_camera(detector, variables, out_dir, **options)


def quantize(export_dir, out_dir, samples, **options):
    from .quantize import quantize_camera
    return quantize_camera(export_dir, out_dir, samples, **options)


def bench_chains(name, runtimes, threads, workdir, repeats):
    from .bench import camera_chains
    return camera_chains(name, runtimes, threads, workdir, repeats)


def stage_name(path):
    from ...profile.counting import part_of
    return part_of(path)


def latency_stages(detector, variables, inputs):
    from .profile import latency_stages as stages
    return stages(detector, variables, inputs)


def size_fields(variables):
    return {}


def train_bench_fields(name, settings):
    from .train_bench import class_fields
    return class_fields()


def train_bench_batches(name, overrides, settings):
    from .train_bench import training_batches
    return training_batches(name, overrides, settings)


def train_bench_note(records, settings):
    from .train_bench import note
    return note(records, settings)


MODALITY = Modality(
    name="image", noun="image", load_samples=load_samples, predictor=predictor, ort_predictor=ort_predictor,
    protocols=PROTOCOLS, fit=fit_camera,
    commands=Commands(refuse=cli.refuse, config_fields=cli.config_fields, train=cli.train,
                      eval_or_predict=cli.eval_or_predict, ship_predictor=cli.ship_predictor, export=cli.export,
                      quantize=cli.quantize),
    export=export, quantize=quantize, bench_chains=bench_chains, stage_name=stage_name,
    latency_stages=latency_stages, size_fields=size_fields, train_bench_fields=train_bench_fields,
    train_bench_batches=train_bench_batches, train_bench_note=train_bench_note, zoo_table=ZOO_TABLE,
)

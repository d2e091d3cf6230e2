"""The camera-image modality (Shuffle-YOLOv3, YOLOv3): RGB images, 2D boxes in pixels, VOC07 AP."""

from __future__ import annotations

from ...data.camera.sources import load_camera_images
from ...profile.counting import part_of
from ..base import Commands, Modality
from . import cli
from .bench import camera_chains
from .evaluate import PROTOCOLS
from .export import export_camera
from .files import READER as FILES
from .fit import fit_camera
from .ort import OrtCameraPredictor
from .predict import CameraPredictor
from .profile import latency_stages
from .quantize import quantize_camera
from .train_bench import class_fields, note, training_batches
from .zoo_table import TABLE as ZOO_TABLE

MODALITY = Modality(
    name="image", noun="image", load_samples=lambda family, *where: load_camera_images(*where),
    predictor=CameraPredictor, ort_predictor=OrtCameraPredictor, protocols=PROTOCOLS, fit=fit_camera,
    commands=Commands(refuse=cli.refuse, config_fields=cli.config_fields, train=cli.train,
                      eval_or_predict=cli.eval_or_predict, ship_predictor=cli.ship_predictor, export=cli.export,
                      quantize=cli.quantize),
    export=export_camera, quantize=quantize_camera, bench_chains=camera_chains, stage_name=part_of,
    latency_stages=latency_stages, size_fields=lambda variables: {},
    # the train bench's camera models take their benchmark's classes, as a training run sets them
    train_bench_fields=lambda name, settings: class_fields(),
    train_bench_batches=training_batches, train_bench_note=note, zoo_table=ZOO_TABLE, files=FILES,
)

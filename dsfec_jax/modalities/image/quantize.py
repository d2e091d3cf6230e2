"""Static INT8 quantization of a camera export (export_camera), calibrated on camera images (the
street benchmark's train split by default): `quantize_camera(EXPORT_DIR, OUT_DIR, images)`.

The same scheme as the other families (quantize.quantize_model: QDQ, int8 weights per output
channel, uint8 activations calibrated over the images); a calibration feed is one image letterboxed
as the export's deploy.json says (modalities/image/ort.graph_input_hw), exactly what the predictor will feed.
The YOLOv3 decode (sigmoid, exp, the anchor arithmetic) comes after the last convolution and stays
float32 (quantize.QUANTIZED_OPS: convolutions and matrix products only).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ...data.camera.batches import eval_input
from ...data.camera.images import CameraImage
from ...models.camera.config import INPUT
from .ort import graph_input_hw
from ...deploy.quantize import batch1_export, write_quantized


def calibration_feeds(manifest: dict, images: Sequence[CameraImage], where="calibration") -> list[dict]:
    """One batch-1 feed per image: {'image': (1, H, W, 3) float32} at the export's input size."""
    feeds = []
    for item in (images[i] for i in range(len(images))):
        hw = graph_input_hw(manifest, item.hw, f"{where} image {item.image_id!r}")
        feeds.append({INPUT: eval_input(item, hw)[0][None]})
    return feeds


def quantize_camera(export_dir: str | Path, out_dir: str | Path, images: Sequence[CameraImage],
                    calibration: str = "minmax", per_channel: bool = True) -> dict:
    """Write OUT_DIR/model.onnx (INT8 QDQ) and its deploy.json -> {'onnx', 'manifest', sizes}."""
    model, manifest = batch1_export(export_dir, "image")
    return write_quantized(model, manifest, out_dir, calibration_feeds(manifest, images, str(model)), per_channel,
                           calibration)

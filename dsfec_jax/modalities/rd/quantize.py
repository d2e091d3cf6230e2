"""Static INT8 quantization of an RD export (export_rd), calibrated on RD samples (the synthetic
train split by default): `quantize_rd(EXPORT_DIR, OUT_DIR, samples)`.

The same scheme as the point models (quantize.quantize_model: QDQ, int8 weights per output channel,
uint8 activations calibrated over the samples); the calibration feeds are the samples' heat / gray
maps fitted as the export's deploy.json says. The DFL decode (softmax, expectation, box arithmetic,
sigmoid) comes after the last convolution and stays float32 (quantize.after_last_conv).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ...data.rd.representations import representations
from ...data.rd.sample import RDSample
from .export import representation_of
from .ort import check_input_size
from ...deploy.quantize import batch1_export, write_quantized


def calibration_feeds(manifest: dict, samples: Sequence[RDSample], where="calibration") -> list[dict]:
    """One batch-1 feed per sample: {input name: (1, H, W, C)} at the export's input size."""
    rep = representation_of(manifest)
    feeds = []
    for sample in samples:
        maps = representations(sample, rep)
        feed = {k: maps[k][None] for k in manifest["inputs"]}
        check_input_size(manifest, feed, f"{where} sample {sample.sample_id!r}")
        feeds.append(feed)
    return feeds


def quantize_rd(export_dir: str | Path, out_dir: str | Path, samples: Sequence[RDSample],
                calibration: str = "minmax", per_channel: bool = True) -> dict:
    """Write OUT_DIR/model.onnx (INT8 QDQ) and its deploy.json -> {'onnx', 'manifest', sizes}."""
    model, manifest = batch1_export(export_dir, "rd")
    return write_quantized(model, manifest, out_dir, calibration_feeds(manifest, samples, str(model)), per_channel,
                           calibration)

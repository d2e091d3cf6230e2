"""Static INT8 quantization of a point-cloud export, calibrated on frames (synthetic by default):
`quantize(EXPORT_DIR, OUT_DIR, frames)` (deploy/quantize.py: what is quantized and how)."""

from __future__ import annotations

from pathlib import Path

from ...data.points.pillarize import pillarize, select_columns
from ...deploy.quantize import batch1_export, write_quantized
from .ort import pillar_spec


def calibration_feeds(manifest: dict, frames) -> list[dict]:
    spec = pillar_spec(manifest)
    feeds = []
    for frame in frames:
        tensors, _ = pillarize(select_columns(frame, spec.features), spec)
        feeds.append({k: tensors[k][None] for k in manifest["inputs"]})
    return feeds


def quantize(export_dir: str | Path, out_dir: str | Path, frames, per_channel: bool = True,
             calibration: str = "minmax") -> dict:
    """Write OUT_DIR/model.onnx (INT8 QDQ) and its deploy.json -> {'onnx', 'manifest', sizes}."""
    model, manifest = batch1_export(export_dir, "points")
    return write_quantized(model, manifest, out_dir, calibration_feeds(manifest, frames), per_channel, calibration)

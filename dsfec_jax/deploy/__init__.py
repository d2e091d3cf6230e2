"""Deploy: export a detector (network + box decoding) to ONNX and to a serialized `jax.export`
artifact, run the ONNX graph with ONNX Runtime from raw input to boxes, and quantize it to INT8:
the modality-free machinery, with the point-cloud pipeline (`export`, `OrtPredictor`, `quantize`).
The range-Doppler and camera ones live in their modality's folder (modalities/rd/{export,ort,
quantize}.py, modalities/image/...), reached through the Modality record; deploy never imports
modalities (re-exporting them here closed an import circle: modalities/rd/export -> deploy)."""

from .export import export
from .ort import OrtPredictor
from .quantize import quantize

__all__ = ["export", "OrtPredictor", "quantize"]

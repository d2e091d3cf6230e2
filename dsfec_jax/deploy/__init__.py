"""Deploy: export a detector (network + box decoding) to ONNX and to a serialized `jax.export`
artifact, run the ONNX graph with ONNX Runtime from raw input to boxes (points: `export`,
`OrtPredictor`; range-Doppler maps: `export_rd`, `OrtRDPredictor`), and quantize it to INT8
(`quantize`, `quantize_rd`)."""

from .export import export
from .export_rd import export_rd
from .ort import OrtPredictor
from .ort_rd import OrtRDPredictor
from .quantize import quantize
from .quantize_rd import quantize_rd

__all__ = ["export", "export_rd", "OrtPredictor", "OrtRDPredictor", "quantize", "quantize_rd"]

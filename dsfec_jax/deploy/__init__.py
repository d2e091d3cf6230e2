"""Deploy: export a detector (network + box decoding) to ONNX and to a serialized `jax.export`
artifact, run the ONNX graph with ONNX Runtime from raw input to boxes (points: `export`,
`OrtPredictor`; range-Doppler maps: `export_rd`, `OrtRDPredictor`; camera images: `export_camera`,
`OrtCameraPredictor`), and quantize it to INT8 (`quantize`, `quantize_rd`, `quantize_camera`)."""

from .export import export
from ..modalities.image.export import export_camera
from ..modalities.rd.export import export_rd
from .ort import OrtPredictor
from ..modalities.image.ort import OrtCameraPredictor
from ..modalities.rd.ort import OrtRDPredictor
from .quantize import quantize
from ..modalities.image.quantize import quantize_camera
from ..modalities.rd.quantize import quantize_rd

__all__ = ["export", "export_camera", "export_rd", "OrtPredictor", "OrtCameraPredictor", "OrtRDPredictor", "quantize",
           "quantize_camera", "quantize_rd"]

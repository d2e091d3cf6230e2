"""Deploy: export a detector (network + box decoding) to ONNX and to a serialized `jax.export`
artifact, run the ONNX graph with ONNX Runtime from raw input to boxes (points: `export`,
`OrtPredictor`; range-Doppler maps: `export_rd`, `OrtRDPredictor`; camera images: `export_camera`,
`OrtCameraPredictor`), and quantize it to INT8 (`quantize`, `quantize_rd`, `quantize_camera`)."""

from .export import export
from .export_camera import export_camera
from .export_rd import export_rd
from .ort import OrtPredictor
from .ort_camera import OrtCameraPredictor
from .ort_rd import OrtRDPredictor
from .quantize import quantize
from .quantize_camera import quantize_camera
from .quantize_rd import quantize_rd

__all__ = ["export", "export_camera", "export_rd", "OrtPredictor", "OrtCameraPredictor", "OrtRDPredictor", "quantize",
           "quantize_camera", "quantize_rd"]

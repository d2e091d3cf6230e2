"""Deploy: export a detector (network + box decoding) to ONNX and to a serialized `jax.export`
artifact, and run the ONNX graph from raw points to boxes with ONNX Runtime."""

from .export import export
from .ort import OrtPredictor

__all__ = ["export", "OrtPredictor"]

"""Deploy machinery, modality-free: export a jittable detector fn to ONNX and to a serialized
`jax.export` artifact with its manifest (`write_export`), run an export's graph with ONNX Runtime
(`read_manifest`, `ort_session`, `run_fixed_batch`), quantize it to INT8 (`quantize_model`,
`write_quantized`) and time it (bench/). Each modality's export, runtime predictor and quantize
verb live in its folder (modalities/points, rd, image: export.py, ort.py, quantize.py) and are
reached through its Modality record (`export`, `ort_predictor`, `quantize`)."""

from .export import grouped, load_jax_export, onnx_model, write_export
from .ort import ort_session, read_manifest, run_fixed_batch
from .quantize import batch1_export, quantize_model, write_quantized

__all__ = ["batch1_export", "grouped", "load_jax_export", "onnx_model", "ort_session", "quantize_model",
           "read_manifest", "run_fixed_batch", "write_export", "write_quantized"]

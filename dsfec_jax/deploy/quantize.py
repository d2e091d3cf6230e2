"""Static INT8 quantization of an exported detector with onnxruntime's tools, the machinery every
modality's quantize verb is built on: `write_quantized(model, manifest, OUT_DIR, feeds)` calibrates
on feeds the modality makes from its samples (modalities/points/quantize.py from point frames,
modalities/rd/quantize.py from RD samples, modalities/image/quantize.py from camera images).

Only the convolutions and matrix products are quantized (QDQ format, symmetric int8 weights
per output channel, activations calibrated by min/max over the calibration frames); the
scatter, the decode (sigmoid, exp, atan2, top-k) and everything after the last conv stay in
float32, because an int8 box code would cost centimetres on every box.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..core import atomic, progress
from .ort import read_manifest

QUANTIZED_OPS = ["Conv", "ConvTranspose", "MatMul", "Gemm"]


def unfold_zeros(path: Path, min_bytes: int = 4096) -> None:
    """Constant folding stores the scatter's all-zero canvas as a 1 MB initializer: put it back
    as a ConstantOfShape node, so the INT8 file is not larger than the float one."""
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.load(str(path))
    graph = model.graph
    for init in list(graph.initializer):
        a = numpy_helper.to_array(init)
        if a.nbytes < min_bytes or a.dtype != np.float32 or a.any():
            continue
        shape = numpy_helper.from_array(np.array(a.shape, np.int64), init.name + "_shape")
        graph.initializer.remove(init)
        graph.initializer.append(shape)
        value = helper.make_tensor("value", onnx.TensorProto.FLOAT, [1], [0.0])
        graph.node.insert(0, helper.make_node("ConstantOfShape", [shape.name], [init.name], value=value))
    onnx.save(model, str(path))


CALIBRATIONS = {"minmax": "MinMax", "percentile": "Percentile", "entropy": "Entropy"}  # -> CalibrationMethod


def quantize_model(src: str | Path, dst: str | Path, feeds: list[dict], per_channel: bool = True,
                   calibration: str = "minmax") -> None:
    """INT8 QDQ copy of the ONNX model at src (any inputs) calibrated on `feeds`, written to dst.
    calibration: activation ranges from min/max, the 99.999th percentile, or entropy."""
    from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType,
                                          quantize_static)
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if not feeds:
        raise ValueError("quantize: no calibration frames")
    if calibration not in CALIBRATIONS:
        raise ValueError(f"quantize: calibration {calibration!r}; expected one of {tuple(CALIBRATIONS)}")
    method = getattr(CalibrationMethod, CALIBRATIONS[calibration])

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.items = iter(feeds)

        def get_next(self):
            return next(self.items, None)

    with tempfile.TemporaryDirectory() as tmp:
        prepared, quantized = Path(tmp) / "prepared.onnx", Path(tmp) / "int8.onnx"
        quant_pre_process(str(src), str(prepared), skip_symbolic_shape=True)  # folds weight transposes
        unfold_zeros(prepared)
        # U8S8 (uint8 activations, int8 weights): ORT's scheme for x86; int8 activations fail to
        # load in ORT 1.31 on jax2onnx's opset-23 graph (QuantizeLinear zero-point type mismatch)
        with progress.stage(f"quantizing to INT8 ({calibration} ranges calibrated on {len(feeds)} inputs)"):
            quantize_static(str(prepared), str(quantized), Reader(), quant_format=QuantFormat.QDQ,
                            op_types_to_quantize=QUANTIZED_OPS, per_channel=per_channel,
                            activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                            calibrate_method=method)
        atomic.write_bytes(Path(dst), quantized.read_bytes())


def batch1_export(export_dir: str | Path, modality: str) -> tuple[Path, dict]:
    """(model path, manifest) of an export to calibrate: batch 1 (a calibration feed is one frame)."""
    model, manifest = read_manifest(export_dir, modality)
    if manifest["batch_size"] != 1:
        raise ValueError(f"{model}: calibrate a batch-1 export (this one has batch {manifest['batch_size']})")
    return model, manifest


def write_quantized(model: Path, manifest: dict, out_dir: str | Path, feeds: list[dict], per_channel: bool,
                    calibration: str) -> dict:
    """Every family's INT8 export: OUT_DIR/model.onnx calibrated on `feeds`, and the export's
    deploy.json with what quantization did -> {'onnx', 'manifest', 'fp32_bytes', 'int8_bytes'}."""
    out_dir = Path(out_dir)
    quantize_model(model, out_dir / "model.onnx", feeds, per_channel, calibration)
    sizes = {"fp32_bytes": model.stat().st_size, "int8_bytes": (out_dir / "model.onnx").stat().st_size}
    info = {**manifest, "quantization": {"format": "QDQ", "weights": "int8 symmetric" + (" per channel" if per_channel else ""),
                                         "activations": f"uint8, {calibration} calibration", "ops": QUANTIZED_OPS,
                                         "calibration_frames": len(feeds), "source_export": str(model), **sizes}}
    atomic.write_json(out_dir / "deploy.json", info)
    return {"onnx": out_dir / "model.onnx", "manifest": out_dir / "deploy.json", **sizes}

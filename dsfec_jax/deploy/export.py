"""The export machinery every modality's export is built on: `write_export` writes a jittable fn
(weights baked in) to DIR as `model.onnx` (jax2onnx), `model.jax_export` (jax.export, serialized)
and `deploy.json` (what a runtime needs around the graph, and how it was made); `grouped` is a
detector in the textbook operators ONNX has; `load_jax_export` reads the artifact back.

Each modality's own export (the graph's inputs, outputs and manifest fields) lives in its folder:
modalities/points/export.py, modalities/rd/export.py, modalities/image/export.py. The depthwise
kernel is exported as a grouped convolution (ONNX `Conv(group=C)`); the shifted form jitted JAX
prefers turns into ~1000 slow ONNX nodes.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

from .. import zoo
from ..core import atomic, progress
from ..core.provenance import versions


def grouped(detector):
    """The same network (same parameters) in the textbook operators ONNX has: the grouped
    depthwise kernel and `kernels="plain"` (Conv and ConvTranspose with constant weights, which
    int8 quantization reads; the training formulations build kernels inside the graph)."""
    textbook = {"depthwise_impl": "grouped", "kernels": "plain"}
    if isinstance(detector, zoo.Detector):
        return detector.replaced(**textbook)  # a BatchNorm-folded detector stays folded
    return zoo.Detector(dataclasses.replace(detector.config, **textbook))


def onnx_model(fn, specs: list, input_names: list[str], output_names: list[str], name: str = "dsfec",
               matmul_einsums: bool = False):
    """jax2onnx of a jittable fn -> ModelProto, stale shape annotations cleared; `matmul_einsums`:
    matrix-product einsums as MatMul (einsums_as_matmuls)."""
    from jax2onnx import to_onnx

    model = to_onnx(fn, specs, model_name=name, input_names=list(input_names), output_names=list(output_names))
    del model.graph.value_info[:]  # stale shape annotations make onnxruntime log one error per layer
    if matmul_einsums:
        einsums_as_matmuls(model)
    return model


def is_matrix_product(equation: str) -> bool:
    """'abcd,de->abce': the last axis of the first operand against a matrix, what MatMul computes
    (leading axes broadcast)."""
    inputs, _, out = equation.replace(" ", "").partition("->")
    a, _, b = inputs.partition(",")
    return len(b) == 2 and len(a) >= 2 and a[-1] == b[0] and b[1] not in a and out == a[:-1] + b[1]


def einsums_as_matmuls(model) -> int:
    """jax2onnx writes a dot of an activation with a matrix (a 1x1 convolution run as a matmul,
    layers/yolo.PaddedConv) as Einsum: rewrite those as MatMul, which ONNX Runtime runs with its
    GEMM kernels and its quantizer turns into int8 (Einsum it leaves in float) -> how many.
    The point families' exports keep their einsums (1-3 per graph, the pillar feature net's linear
    layers on raw point features): as MatMul they would be quantized, which their INT8 figures do
    not cover."""
    count = 0
    for node in model.graph.node:
        equation = next((a.s.decode() for a in node.attribute if a.name == "equation"), "")
        if node.op_type == "Einsum" and len(node.input) == 2 and is_matrix_product(equation):
            node.op_type = "MatMul"
            del node.attribute[:]
            count += 1
    return count


# what a deploy manifest records besides jax's own: the converter and the runtime it was checked with
DEPLOY_VERSIONS = ("jax", "jaxlib", "flax", "numpy", "jax2onnx", "onnx", "onnxruntime", "dsfec_jax")


def write_export(fn, specs: list, input_names, output_names, out_dir: str | Path, name: str, fields: dict,
                 source: dict | None = None, jax_export: bool = True, matmul_einsums: bool = False) -> dict:
    """Every family's export: fn (weights baked in) as out_dir/model.onnx and, with `jax_export`,
    out_dir/model.jax_export; deploy.json holds `fields` (what a runtime needs around the graph)
    plus the graph's inputs, outputs and shapes, its opset and size, `source` (command, weights)
    and the versions -> {'onnx', 'jax_export' (when written), 'manifest'}. `matmul_einsums`: see
    onnx_model."""
    out_dir = Path(out_dir)
    with progress.stage(f"exporting {name} to ONNX (tracing it with jax2onnx)"):
        model = onnx_model(fn, specs, input_names, output_names, name, matmul_einsums)
    atomic.write_bytes(out_dir / "model.onnx", model.SerializeToString())
    paths = {"onnx": out_dir / "model.onnx"}
    if jax_export:
        with progress.stage(f"exporting {name} with jax.export (lowering it to StableHLO)"):
            exported = jax.export.export(jax.jit(fn))(*specs)
        atomic.write_bytes(out_dir / "model.jax_export", exported.serialize())
        paths["jax_export"] = out_dir / "model.jax_export"
    atomic.write_json(out_dir / "deploy.json", {
        **fields, "inputs": list(input_names), "outputs": list(output_names),
        "input_shapes": {k: list(s.shape) for k, s in zip(input_names, specs)},
        "onnx": {"opset": model.opset_import[0].version, "nodes": len(model.graph.node)},
        "source": source or {}, "versions": versions(DEPLOY_VERSIONS)})
    return {**paths, "manifest": out_dir / "deploy.json"}


def load_jax_export(path: str | Path):
    """The serialized jax.export artifact -> a callable (the export's inputs, in order) -> outputs."""
    return jax.export.deserialize(bytearray(Path(path).read_bytes())).call

"""Export one detector to DIR: `model.onnx` (jax2onnx), `model.jax_export` (jax.export,
serialized) and `deploy.json` (what a runtime needs around the graph, and how it was made).

The graph is pillar tensors -> pillar feature net -> scatter -> backbone -> neck -> heads ->
decode (sigmoid, box decode, top-k): DSFEC gives boxes (B, K, 5) as x, y, w, l, yaw, a
CenterHead (RadarNeXt) boxes (B, K, 7) as x, y, z, w, l, h, yaw with IoU-rescored scores;
scores (B, K); labels (B, K). Pillarization and rotated NMS stay on the host, as in the
field's deploy tools. The depthwise kernel is exported as a grouped convolution (ONNX
`Conv(group=C)`); the shifted form jitted JAX prefers turns into ~1000 slow ONNX nodes.
A re-parameterizable model (RadarNeXt) is exported in its fused form (`zoo.deploy`); its DCNv3
bilinear sampling becomes ONNX gathers. `write_export` (graph, artifact, manifest) is every family's:
export_rd.py writes the range-Doppler models with it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

from .. import zoo
from ..core import atomic
from ..core.provenance import versions
from ..modalities.points.predict import decoder, head_classes

INPUTS = ("points", "mask", "coords")
OUTPUTS = ("boxes", "scores", "labels")


def map_outputs(cfg) -> tuple[str, ...]:
    """Names of the head maps `with_maps` adds to the outputs (what parity tests compare)."""
    return zoo.family_of(cfg).points.map_outputs(cfg)


def head_maps(cfg, maps: dict) -> tuple:
    """The network's outputs in `map_outputs(cfg)` order (a training-only corner map is left out)."""
    return zoo.family_of(cfg).points.head_maps(cfg, maps)


def end_to_end(detector, variables, top_k: int = 100, with_maps: bool = False):
    """fn(points, mask, coords) -> (boxes, scores, labels[, head maps...]), weights baked in."""
    decode = decoder(detector.config, top_k)

    def fn(points, mask, coords):
        maps = detector.apply(variables, {"points": points, "mask": mask, "coords": coords})
        out = decode(maps)
        return out + head_maps(detector.config, maps) if with_maps else out

    return fn


def grouped(detector):
    """The same network (same parameters) in the textbook operators ONNX has: the grouped
    depthwise kernel and `kernels="plain"` (Conv and ConvTranspose with constant weights, which
    int8 quantization reads; the training formulations build kernels inside the graph)."""
    return zoo.Detector(dataclasses.replace(detector.config, depthwise_impl="grouped", kernels="plain"))


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
    model = onnx_model(fn, specs, input_names, output_names, name, matmul_einsums)
    atomic.write_bytes(out_dir / "model.onnx", model.SerializeToString())
    paths = {"onnx": out_dir / "model.onnx"}
    if jax_export:
        exported = jax.export.export(jax.jit(fn))(*specs)
        atomic.write_bytes(out_dir / "model.jax_export", exported.serialize())
        paths["jax_export"] = out_dir / "model.jax_export"
    atomic.write_json(out_dir / "deploy.json", {
        **fields, "inputs": list(input_names), "outputs": list(output_names),
        "input_shapes": {k: list(s.shape) for k, s in zip(input_names, specs)},
        "onnx": {"opset": model.opset_import[0].version, "nodes": len(model.graph.node)},
        "source": source or {}, "versions": versions(DEPLOY_VERSIONS)})
    return {**paths, "manifest": out_dir / "deploy.json"}


def export(detector, variables, out_dir: str | Path, top_k: int = 100, batch_size: int = 1,
           with_maps: bool = False, source: dict | None = None) -> dict:
    """Write model.onnx, model.jax_export and deploy.json to out_dir -> {name: path}."""
    detector, variables = zoo.deploy(detector, variables)  # fused form (unchanged for DSFEC)
    det = grouped(detector)
    cfg = det.config
    outputs = OUTPUTS + (map_outputs(cfg) if with_maps else ())
    specs = [jax.ShapeDtypeStruct(v.shape, v.dtype) for v in (det.dummy_inputs(batch_size)[k] for k in INPUTS)]
    fields = {"model": cfg.name, "modality": "points", "top_k": top_k, "batch_size": batch_size,
              "pillars": {"grid": dataclasses.asdict(cfg.grid), "features": list(cfg.point_features),
                          "max_pillars": cfg.max_pillars, "max_points": cfg.max_points},
              "head_classes": {h: list(c) for h, c in head_classes(cfg).items()}}
    return write_export(end_to_end(det, variables, top_k, with_maps), specs, INPUTS, outputs, out_dir, det.name,
                        fields, source)


def load_jax_export(path: str | Path):
    """The serialized jax.export artifact -> a callable (the export's inputs, in order) -> outputs."""
    return jax.export.deserialize(bytearray(Path(path).read_bytes())).call

"""Export one detector to DIR: `model.onnx` (jax2onnx), `model.jax_export` (jax.export,
serialized) and `deploy.json` (what a runtime needs around the graph, and how it was made).

The graph is pillar tensors -> pillar feature net -> scatter -> backbone -> neck -> heads ->
decode (sigmoid, box decode, top-k): DSFEC gives boxes (B, K, 5) as x, y, w, l, yaw, a
CenterHead (RadarNeXt) boxes (B, K, 7) as x, y, z, w, l, h, yaw with IoU-rescored scores;
scores (B, K); labels (B, K). Pillarization and rotated NMS stay on the host, as in the
field's deploy tools. The depthwise kernel is exported as a grouped convolution (ONNX
`Conv(group=C)`); the shifted form jitted JAX prefers turns into ~1000 slow ONNX nodes.
A re-parameterizable model (RadarNeXt) is exported in its fused form (`zoo.deploy`); its DCNv3
bilinear sampling becomes ONNX gathers.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

from .. import zoo
from ..core import atomic
from ..core.provenance import versions
from ..predict import decoder, head_classes

INPUTS = ("points", "mask", "coords")
OUTPUTS = ("boxes", "scores", "labels")


def map_outputs(cfg) -> tuple[str, ...]:
    """Names of the head maps `with_maps` adds to the outputs (what parity tests compare)."""
    return zoo.family_of(cfg).map_outputs(cfg)


def head_maps(cfg, maps: dict) -> tuple:
    """The network's outputs in `map_outputs(cfg)` order (a training-only corner map is left out)."""
    return zoo.family_of(cfg).head_maps(cfg, maps)


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


def onnx_model(fn, specs: list, input_names: list[str], output_names: list[str], name: str = "dsfec"):
    """jax2onnx of a jittable fn -> ModelProto, stale shape annotations cleared."""
    from jax2onnx import to_onnx

    model = to_onnx(fn, specs, model_name=name, input_names=list(input_names), output_names=list(output_names))
    del model.graph.value_info[:]  # stale shape annotations make onnxruntime log one error per layer
    return model


def export(detector, variables, out_dir: str | Path, top_k: int = 100, batch_size: int = 1,
           with_maps: bool = False, source: dict | None = None) -> dict:
    """Write model.onnx, model.jax_export and deploy.json to out_dir -> {name: path}."""
    out_dir = Path(out_dir)
    detector, variables = zoo.deploy(detector, variables)  # fused form (unchanged for DSFEC)
    det = grouped(detector)
    outputs = OUTPUTS + (map_outputs(det.config) if with_maps else ())
    fn = end_to_end(det, variables, top_k, with_maps)
    specs = [jax.ShapeDtypeStruct(v.shape, v.dtype) for v in (det.dummy_inputs(batch_size)[k] for k in INPUTS)]
    model = onnx_model(fn, specs, INPUTS, outputs, det.name)
    atomic.write_bytes(out_dir / "model.onnx", model.SerializeToString())
    exported = jax.export.export(jax.jit(fn))(*specs)
    atomic.write_bytes(out_dir / "model.jax_export", exported.serialize())
    cfg = det.config
    atomic.write_json(out_dir / "deploy.json", {
        "model": cfg.name, "top_k": top_k, "batch_size": batch_size, "inputs": list(INPUTS), "outputs": list(outputs),
        "input_shapes": {k: list(s.shape) for k, s in zip(INPUTS, specs)},
        "pillars": {"grid": dataclasses.asdict(cfg.grid), "features": list(cfg.point_features),
                    "max_pillars": cfg.max_pillars, "max_points": cfg.max_points},
        "head_classes": {h: list(c) for h, c in head_classes(cfg).items()},
        "onnx": {"opset": model.opset_import[0].version, "nodes": len(model.graph.node)},
        "source": source or {}, "versions": versions()})
    return {"onnx": out_dir / "model.onnx", "jax_export": out_dir / "model.jax_export",
            "manifest": out_dir / "deploy.json"}


def load_jax_export(path: str | Path):
    """The serialized jax.export artifact -> a callable (points, mask, coords) -> outputs."""
    return jax.export.deserialize(bytearray(Path(path).read_bytes())).call

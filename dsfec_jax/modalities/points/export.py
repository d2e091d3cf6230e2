"""Export one point-cloud detector (DSFEC, RadarNeXt) to DIR with deploy/export.write_export:
`model.onnx` (jax2onnx), `model.jax_export` (jax.export, serialized) and `deploy.json`.

The graph is pillar tensors -> pillar feature net -> scatter -> backbone -> neck -> heads ->
decode (sigmoid, box decode, top-k): DSFEC gives boxes (B, K, 5) as x, y, w, l, yaw, a
CenterHead (RadarNeXt) boxes (B, K, 7) as x, y, z, w, l, h, yaw with IoU-rescored scores;
scores (B, K); labels (B, K). Pillarization and rotated NMS stay on the host, as in the
field's deploy tools. The depthwise kernel is exported as a grouped convolution (ONNX
`Conv(group=C)`, deploy/export.grouped); the shifted form jitted JAX prefers turns into ~1000 slow
ONNX nodes. A re-parameterizable model (RadarNeXt) is exported in its fused form (`zoo.deploy`);
its DCNv3 bilinear sampling becomes ONNX gathers.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

from ... import zoo
from ...deploy.export import grouped, write_export
from .predict import decoder, head_classes

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


def export(detector, variables, out_dir: str | Path, top_k: int = 100, batch_size: int = 1,
           with_maps: bool = False, source: dict | None = None) -> dict:
    """Write model.onnx, model.jax_export and deploy.json to out_dir -> {name: path}."""
    # the inference form (re-parameterized, BatchNorm folded), every conv kept a Conv node
    detector, variables = zoo.deploy(detector, variables, for_export=True)
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

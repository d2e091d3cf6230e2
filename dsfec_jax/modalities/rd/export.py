"""Export one YOLO-RD detector (YOLOv8/v9t/v10n, with or without the Adapter) to DIR: `model.onnx`
(jax2onnx), optionally `model.jax_export`, and `deploy.json`, with export.write_export as every family.

The graph is network -> DFL decode (the representations are made on the host, as for the JAX
predictor): inputs named by the config's `input_names` ('heat' (B, H, W, 3), 'gray' (B, H, W, 1))
at one fixed size; outputs `boxes` (B, A, 4) xyxy in input
pixels and `scores` (B, A, nc), the sigmoid class scores of every anchor (A = H W / 64 + H W / 256 +
H W / 1024: 336 at 256 x 64). YOLOv10 exports its one-to-one maps (net.inference_maps), the ones it
infers with. The post-processing stays on the host (models/yolo_rd/decode_host.host_detections): class-aware greedy NMS
(boxes/nms2d), or YOLOv10's NMS-free top-k; deploy.json says which and with what settings.

Why NMS is not in the graph: in ONNX Runtime the compiled NMS (boxes/nms2d.nms_jax, one greedy pass
over all A x nc multi-label candidates in a `fori_loop`) becomes an ONNX Loop of A x nc iterations,
many times slower than the host NMS on the same candidates (the timings: docs/range-doppler.md,
"Deploy"; `dsfec bench --models yolov8n --runtimes jax,onnx --threads 1` re-measures). jax2onnx
also has no batching rule for its Loop, so the graph would be batch 1 only.

The fitted input size is part of the graph: deploy.json records the representation (colormap, fit,
input_hw) that turns a map into exactly that size, and the predictor refuses a map that fits to
another size.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

from ... import zoo
from ...core.provenance import jsonable
from ...data.rd.representations import RDRepresentation, fitted_shape
from ...models.yolo_rd.decode import EVAL_CONF, EVAL_IOU, EVAL_MAX_DET, decode
from ...models.yolo_rd.decode_host import NMS, TOP_K
from ...models.yolo_rd.net import inference_maps
from ...deploy.export import write_export

OUTPUTS = ("boxes", "scores")  # per anchor: xyxy input pixels, class scores


def decoded_network(detector, variables):
    """fn(*maps in `input_names` order) -> (boxes (B, A, 4), class scores (B, A, nc)): the network
    and the DFL decode, weights baked in (what model.onnx holds)."""
    cfg = detector.config

    def fn(*maps):
        outputs = detector.apply(variables, dict(zip(cfg.input_names, maps)))
        return decode(inference_maps(outputs), cfg.strides, cfg.reg_max)

    return fn


def postprocess_kind(detector, variables, specs) -> str:
    """TOP_K for a network with a one-to-one head (YOLOv10: its outputs are a dict, the rule
    modalities/rd/predict.detecting_network follows), else NMS."""
    names = detector.config.input_names
    outputs = jax.eval_shape(lambda v, *maps: detector.apply(v, dict(zip(names, maps))), variables, *specs)
    return TOP_K if isinstance(outputs, dict) else NMS


def input_specs(cfg, input_hw: tuple[int, int], batch_size: int) -> list:
    """One ShapeDtypeStruct per input, in `input_names` order."""
    maps = cfg.dummy_inputs(batch_size, hw=tuple(input_hw))
    return [jax.ShapeDtypeStruct(maps[k].shape, maps[k].dtype) for k in cfg.input_names]


def export_representation(input_hw: tuple[int, int], representation: RDRepresentation | None) -> RDRepresentation:
    """The representation that fits maps to the graph's size: by default pad (maps up to input_hw,
    the native 256 x 64 RD map as it is); a given one must fit to exactly input_hw."""
    rep = representation or RDRepresentation(input_hw=tuple(input_hw))
    if rep.fit == "resize" and tuple(rep.input_hw) != tuple(input_hw):
        raise ValueError(f"representation input_hw {rep.input_hw} differs from the export's input_hw {input_hw}")
    if fitted_shape(tuple(input_hw), rep) != tuple(input_hw):
        raise ValueError(f"input_hw {tuple(input_hw)}: the representation (fit {rep.fit!r}, stride {rep.stride}) "
                         f"fits such a map to {fitted_shape(tuple(input_hw), rep)}; give multiples of {rep.stride}")
    return rep


def export_rd(detector, variables, out_dir: str | Path, source: dict | None = None,
              input_hw: tuple[int, int] = (256, 64), batch_size: int = 1,
              representation: RDRepresentation | None = None, jax_export: bool = True) -> dict[str, Path]:
    """Write model.onnx, deploy.json and (with `jax_export`) model.jax_export to out_dir -> {name: path}.
    input_hw: the fitted (range rows, Doppler columns) the graph takes; representation: how maps
    reach it (default: pad to input_hw)."""
    from ..checks import require_modality

    require_modality(detector.config, "rd", "export_rd")
    # the inference form (BatchNorm folded into the convs), every conv kept a Conv node
    detector, variables = zoo.deploy(detector, variables, for_export=True)
    cfg = detector.config
    rep = export_representation(input_hw, representation)
    specs = input_specs(cfg, input_hw, batch_size)
    kind = postprocess_kind(detector, variables, specs)
    fields = {"model": cfg.name, "modality": "rd", "config": jsonable(cfg), "batch_size": batch_size,
              "input_hw": list(input_hw), "classes": list(cfg.classes), "representation": jsonable(rep),
              "postprocess": {"kind": kind, "where": "host", "multi_label": True, "iou_threshold": EVAL_IOU,
                              "score_threshold": EVAL_CONF, "max_detections": EVAL_MAX_DET}}
    # matmul_einsums: the 1x1 convs (run as dots, layers/yolo.PaddedConv) become MatMul, which ORT
    # runs faster and quantizes (24 of yolov8n's 63 convs; the timings: docs/range-doppler.md,
    # "Deploy").
    return write_export(decoded_network(detector, variables), specs, cfg.input_names, OUTPUTS, out_dir, cfg.name,
                        fields, source, jax_export, matmul_einsums=True)


def representation_of(manifest: dict) -> RDRepresentation:
    """The RDRepresentation an RD export's deploy.json records."""
    rep = dict(manifest["representation"])
    if rep.get("input_hw") is not None:
        rep["input_hw"] = tuple(rep["input_hw"])
    fields = {f.name for f in dataclasses.fields(RDRepresentation)}
    return RDRepresentation(**{k: v for k, v in rep.items() if k in fields})

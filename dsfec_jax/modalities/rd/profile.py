"""What the profiler does differently for range-Doppler models (modality 'rd': the YOLO-RD family).

- Stages. Params and GFLOPs are grouped by the network's top-level parts, `backbone`, `adapter`
  (Adapter models only: its Stem and Exchangers), `neck` and `head` (counting.part_of): module
  paths say which part a layer belongs to, so the Adapter is a stage of its own although its
  Exchangers run between backbone layers. For the same reason it cannot be timed alone: latency
  stages are `features` (backbone + Adapter), `neck` and `head` (models/yolo_rd/net.py's stage
  methods).
- Inputs. The real input size: 256 x 64 RD maps (`cfg.dummy_inputs`, the synthetic benchmark's and
  RADDet's map size), batch 1, every representation the network reads (heat, and gray for the Adapter).
- Params, two conventions. `params` counts the trainable 'params' collection, as for every family.
  `params_folded` is ultralytics' `fuse()` summary, the convention of the paper's Tables 3-4
  (models/yolo_rd/paper.py: s and m and every Table 4 entry are folded counts, l is unfolded,
  n is both to the printed digits): every BatchNorm folded into the conv before it (its scale and
  shift become the conv's bias: C parameters fewer per BN), every RepConvN's 1x1 branch folded into
  its 3x3 and every RepVGGDW's 3x3 branch into its 7x7 (the folded kernel and one bias fewer).
- GFLOPs. 2 x MACs of the conv layers (profile/counting.py), as ultralytics' thop count (MACs x 2;
  ../shared/docs/rd-yolo-camera-facts.md §2): pooling, upsampling, the attention's matmuls and the
  parameter-free DFL decode are not counted. YOLOv10n counts both of its heads, as its trained
  network computes both (inference decodes only the one-to-one maps). `ultralytics_gflops` counts
  at ultralytics' published setting (640 x 640, nc = 80) to check against its model tables.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ... import zoo
from ...profile import counting

LATENCY_STAGES = ("features", "neck", "head")
FOLDED_CONVENTION = ("ultralytics fuse(): params less every BN's scale (folded into its conv's bias), "
                     "RepConvN 1x1 and RepVGGDW 3x3 branches folded into their larger kernels")
FLOPS_CONVENTION = ("2 x MACs of conv layers at batch 1 on the 256 x 64 maps (ultralytics' thop convention, "
                    "MACs x 2); pooling, upsampling, attention matmuls and the DFL decode not counted")
ULTRALYTICS_SETTING = {"hw": (640, 640), "classes": 80}


def folded_params(tree) -> int:
    """Parameters of a 'params' tree after ultralytics' `fuse()` (see the module docstring)."""
    if not isinstance(tree, dict):
        return int(np.prod(tree.shape))
    total = sum(folded_params(v) for k, v in tree.items() if k != "scale")  # a BN's scale folds away
    kernel = lambda name: tree[name]["conv"]["kernel"].shape
    # RepConvN (layers/yolo_gelan.py): 3x3 `conv1` + 1x1 `conv2`, summed
    if {"conv1", "conv2"} <= set(tree) and "conv" in tree["conv2"] and kernel("conv2")[:2] == (1, 1):
        total -= int(np.prod(kernel("conv2"))) + kernel("conv2")[-1]
    # RepVGGDW (layers/yolo_v10.py): depthwise 7x7 `conv` + 3x3 `conv1`, summed
    if {"conv", "conv1"} <= set(tree) and "conv" in tree["conv"] and kernel("conv")[0] == 7:
        total -= int(np.prod(kernel("conv1"))) + kernel("conv1")[-1]
    return total


def size_fields(variables: dict) -> dict:
    """The RD record's own size fields (and its FLOPs convention in place of the point families')."""
    return {"params_folded": folded_params(variables["params"]), "params_folded_convention": FOLDED_CONVENTION,
            "gflops_convention": FLOPS_CONVENTION}


def latency_stages(detector, variables, inputs) -> dict:
    """Jitted stage callables (not blocking; profile/latency.py wraps them): features (backbone with the
    Adapter's exchanges), neck, head, each on the previous stage's output."""
    feats_fn = jax.jit(lambda v, x: detector.apply_method(v, "features", x))
    neck_fn = jax.jit(lambda v, f: detector.apply_method(v, "neck_outputs", f))
    head_fn = jax.jit(lambda v, n: detector.apply_method(v, "head_outputs", n))
    feats = feats_fn(variables, inputs)
    neck = neck_fn(variables, feats)
    return {"features": lambda: feats_fn(variables, inputs), "neck": lambda: neck_fn(variables, feats),
            "head": lambda: head_fn(variables, neck)}


def ultralytics_gflops(name: str, hw: tuple[int, int] = ULTRALYTICS_SETTING["hw"],
                       classes: int = ULTRALYTICS_SETTING["classes"]) -> dict:
    """Analytic GFLOPs of zoo model `name` at ultralytics' published setting (640 x 640, nc = 80),
    traced from shapes only. ultralytics' model table (docs/en/models/yolov8.md) lists YOLOv8n at
    8.7 and YOLOv8s at 28.6 GFLOPs: its fused summary ("YOLOv8n summary (fused) ... 8.7 GFLOPs"),
    conv MACs x 2; the unfused summary in cfg/models/v8/yolov8.yaml (8.9) adds thop's BN ops."""
    cfg = zoo.config(name)
    cfg = dataclasses.replace(cfg, classes=tuple(f"class{i}" for i in range(classes)))
    return counting.count_gflops(zoo.Detector(cfg), cfg.dummy_inputs(1, hw=hw), counting.part_of)

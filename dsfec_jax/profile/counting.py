"""Parameters and FLOPs, counted analytically per layer and cross-checked against XLA.

Conventions (stated in every record):
- params: the 'params' collection (conv/linear weights, biases, BN scale and offset); BN moving
  statistics ('batch_stats') are state, not parameters, and are not counted.
- GFLOPs = 2 x MACs of convs, deconvs and per-point linears, batch 1, as DSFEC and most
  detection papers quote them; elementwise work (BN, activations, adds) is not counted.
  Transposed convs count only the non-zero taps. The pillar net is counted on all of its
  max_pillars x max_points slots, because the dense tensor is what runs.
- stages: the caller's grouping of module paths (its modality's `stage_name`): a point network's
  top-level modules grouped into stem, stage1..4, neck, heads, pillar_net
  (modalities/points/profile.stage_of); a range-Doppler network's top-level parts as they are:
  backbone, adapter, neck, head (`part_of`, the default); so are a camera network's: backbone,
  head (the YOLOv3 FPN and its three output convs).
"""

from __future__ import annotations

import collections
import dataclasses

import flax.linen as nn
import jax
import numpy as np

PARAMS_CONVENTION = "params collection (weights, biases, BN scale/offset); BN moving stats excluded"
FLOPS_CONVENTION = "2 x MACs of conv/deconv/linear layers at batch 1; pillar net on all P x N slots"


def part_of(path: tuple[str, ...]) -> str:
    """A module path's top-level part (a range-Doppler or camera network's backbone, adapter, neck,
    head): the grouping when the caller names none."""
    return path[0] if path else "?"


def count_params(variables: dict, stage_name=part_of) -> dict:
    """Total and per-stage parameter counts of a variables tree (`stage_name`: module path -> stage)."""
    per_stage: dict[str, int] = collections.Counter()
    for path, leaf in jax.tree_util.tree_flatten_with_path(variables["params"])[0]:
        per_stage[stage_name((path[0].key,))] += int(np.prod(leaf.shape))
    return {"total": sum(per_stage.values()), "per_stage": dict(per_stage)}


def layer_macs(detector, batch_size: int = 1, inputs: dict | None = None) -> list[tuple[tuple[str, ...], str, int]]:
    """(module path, layer kind, MACs) for every counted layer, traced without computing, on
    `inputs` (arrays or shape structs; default `detector.dummy_inputs(batch_size)`)."""
    rows = []

    def interceptor(next_fun, args, kwargs, context):
        out = next_fun(*args, **kwargs)
        module = context.module
        if context.method_name == "__call__" and hasattr(module, "macs"):
            rows.append((tuple(module.path), type(module).__name__, int(module.macs(args[0].shape, out.shape))))
        return out

    inputs = detector.dummy_inputs(batch_size) if inputs is None else inputs
    variables = jax.eval_shape(detector.init, jax.random.key(0))
    with nn.intercept_methods(interceptor):
        jax.eval_shape(detector.apply, variables, inputs)
    return rows


def count_gflops(detector, inputs: dict | None = None, stage_name=part_of) -> dict:
    """Analytic GFLOPs (2 x MACs) in total and per stage (`stage_name`: module path -> stage, the
    modality's `Modality.stage_name`), at batch 1 (or on `inputs`)."""
    per_stage: dict[str, float] = collections.Counter()
    for path, _, macs in layer_macs(detector, 1, inputs):
        per_stage[stage_name(path)] += 2 * macs / 1e9
    return {"total": sum(per_stage.values()), "per_stage": dict(per_stage)}


def textbook(detector):
    """The same network (same parameters) in its textbook operators (`kernels="plain"`, where the
    config has that field), the network the analytic count describes: the training formulation
    of a stride-2 deconv (sub-pixel) also multiplies the zero taps of the dilated form, which XLA
    would count (DSFEC-S: +3.5 %)."""
    if not hasattr(detector.config, "kernels"):
        return detector
    return type(detector)(dataclasses.replace(detector.config, kernels="plain"))


def compile_network(detector, variables, inputs):
    """The compiled batch-1 network (textbook operators), for XLA's cost and memory analyses."""
    return jax.jit(textbook(detector).apply).lower(variables, inputs).compile()


def xla_gflops(compiled) -> float:
    """XLA's own cost analysis of the compiled network (includes elementwise work)."""
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    return float(cost["flops"]) / 1e9

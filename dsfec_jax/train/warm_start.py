"""Start a network from another's trained variables, module by module.

A top-level module (`stem`, `stage2_block3`, `head_car`, ...) is copied when the source has a
module of that name whose every leaf has the same shape; the rest keep their fresh
initialisation. This is how a depth candidate inherits a trained network: the subnet with the
first k blocks of a stage takes exactly those k blocks (elastic depth in Once-for-All, Cai et
al. 2020), and a deeper candidate keeps fresh blocks past the source's depth.

`LeadingSlices(source)` also seeds modules whose widths differ: each leaf takes the source's
leading block (W[:min(c_out), :min(c_in)], Once-for-All's elastic width without its channel
sorting) and keeps its fresh values past the source's widths. The one-shot NAS starts its
width supernet and the subnets it retrains stand-alone this way from the base's shipped weights.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np


@dataclasses.dataclass(frozen=True)
class LeadingSlices:
    """Trained variables that seed a network of other widths through their leading channels."""

    variables: dict


def _leading(fresh, trained):
    out = np.array(fresh, copy=True)
    trained = np.asarray(trained)
    block = tuple(slice(0, min(a, b)) for a, b in zip(out.shape, trained.shape))
    out[block] = trained[block]
    return out


def _same_shapes(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return (jax.tree.structure(a) == jax.tree.structure(b)
            and all(np.shape(x) == np.shape(y) for x, y in zip(la, lb)))


def warm_start(variables: dict, source) -> tuple[dict, dict]:
    """(fresh variables, trained source variables) -> (merged variables, {'copied': [...],
    'fresh': [...]}) over top-level module names; params and batch_stats move together.
    A `LeadingSlices` source also fills modules of the same structure and other widths
    ({'sliced': [...]})."""
    if isinstance(source, LeadingSlices):
        return _warm_start_leading(variables, source.variables)
    params, src = variables["params"], source["params"]
    copied = sorted(k for k in params if k in src and _same_shapes(params[k], src[k])
                    and _same_shapes(variables.get("batch_stats", {}).get(k, {}),
                                     source.get("batch_stats", {}).get(k, {})))
    merged = {}
    for collection in ("params", "batch_stats"):
        fresh, trained = variables.get(collection, {}), source.get(collection, {})
        merged[collection] = {k: jax.tree.map(np.asarray, trained[k]) if k in copied and k in trained else v
                              for k, v in fresh.items()}
    return merged, {"copied": copied, "fresh": sorted(k for k in params if k not in copied)}


def _same_structure(a, b) -> bool:
    return jax.tree.structure(a) == jax.tree.structure(b) and all(
        np.ndim(x) == np.ndim(y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def _warm_start_leading(variables: dict, source: dict) -> tuple[dict, dict]:
    merged, copied, sliced = {}, [], []
    for k, fresh in variables["params"].items():
        if k in source["params"] and _same_structure(fresh, source["params"][k]):
            (copied if _same_shapes(fresh, source["params"][k]) else sliced).append(k)
    for collection in ("params", "batch_stats"):
        fresh, trained = variables.get(collection, {}), source.get(collection, {})
        merged[collection] = {k: jax.tree.map(_leading, v, trained[k]) if k in copied + sliced and k in trained
                              and _same_structure(v, trained[k]) else v for k, v in fresh.items()}
    return merged, {"copied": sorted(copied), "sliced": sorted(sliced),
                    "fresh": sorted(k for k in variables["params"] if k not in copied + sliced)}

"""Start a network from another's trained variables, module by module.

A top-level module (`stem`, `stage2_block3`, `head_car`, ...) is copied when the source has a
module of that name whose every leaf has the same shape; the rest keep their fresh
initialisation. This is how a depth candidate inherits a trained network: the subnet with the
first k blocks of a stage takes exactly those k blocks (elastic depth in Once-for-All, Cai et
al. 2020), and a deeper candidate keeps fresh blocks past the source's depth.
"""

from __future__ import annotations

import jax
import numpy as np


def _same_shapes(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return (jax.tree.structure(a) == jax.tree.structure(b)
            and all(np.shape(x) == np.shape(y) for x, y in zip(la, lb)))


def warm_start(variables: dict, source: dict) -> tuple[dict, dict]:
    """(fresh variables, trained source variables) -> (merged variables, {'copied': [...],
    'fresh': [...]}) over top-level module names; params and batch_stats move together."""
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

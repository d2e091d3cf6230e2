"""DSFEC's Table 2 memory convention: the stem's input and output maps (float32, batch 1) plus the
stem's weights, in MiB. It reproduces the paper's 4.32 / 2.74 / 2.35 / 1.96 MB for 32 / 16 / 12 / 8
stem filters to 0.25 % (the convention is inferred by fitting those four published figures)."""

from __future__ import annotations

import jax
import numpy as np

MIB = 2**20


def stem_memory_mb(cfg, variables: dict) -> float:
    nx, ny = cfg.grid.shape
    maps = nx * ny * cfg.in_channels
    for _ in range(cfg.stem_convs):
        maps += nx * ny * cfg.stem_filters  # each stem conv keeps full resolution
    stem_weights = sum(
        int(np.prod(leaf.shape))
        for name, sub in variables["params"].items() if name.startswith("stem")
        for leaf in jax.tree.leaves(sub)
    )
    return 4 * (maps + stem_weights) / MIB

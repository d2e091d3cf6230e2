"""Memory figures.

`paper_memory_mb` is the DSFEC Table 2 convention, which the fit doc (§3 A.4) identifies as the
stem's input and output maps (float32, batch 1) plus the stem's weights, in MiB: it reproduces
4.32 / 2.74 / 2.35 / 1.96 MB for 32 / 16 / 12 / 8 stem filters to 0.25 %. `xla_peak_mb` is what
XLA reserves for temporaries plus arguments and outputs of the compiled network: a fuller,
less comparable figure.
"""

from __future__ import annotations

import jax
import numpy as np

MIB = 2**20


def paper_memory_mb(detector, variables) -> float | None:
    """DSFEC's stem-memory figure; None for families without a DSFEC stem (use xla_peak_mb)."""
    cfg = detector.config
    if cfg.family != "dsfec":
        return None
    nx, ny = cfg.grid.shape
    maps = nx * ny * cfg.in_channels
    for i in range(cfg.stem_convs):
        maps += nx * ny * cfg.stem_filters  # each stem conv keeps full resolution
    stem_weights = sum(
        int(np.prod(leaf.shape))
        for name, sub in variables["params"].items() if name.startswith("stem")
        for leaf in jax.tree.leaves(sub)
    )
    return 4 * (maps + stem_weights) / MIB


def xla_peak_mb(compiled) -> float:
    mem = compiled.memory_analysis()
    if mem is None:
        return float("nan")
    total = mem.temp_size_in_bytes + mem.argument_size_in_bytes + mem.output_size_in_bytes
    return total / MIB

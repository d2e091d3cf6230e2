"""Interleaved timing of the chains, raw input to boxes, one call per stage.

A chain is [(stage, fn(previous output) -> output)]: a predictor's own path from raw input to
detections, `predictor.stages(items)` (modalities/stages.py), so the bench times what users run
(modalities/<m>/bench.py: points pillarize, network_decode, nms; range-Doppler maps
representation, network_decode, nms, to_map; camera images letterbox, network_decode, nms,
to_image). Every runtime runs its predictor's chain on the same frame; within each repeat the
models and runtimes alternate (A B C A B C ...) rather than running one after the other, so a slow
spell of a noisy shared machine hits them all alike and their ratios hold.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

from ...core import progress


def time_chains(chains: dict, repeats: int, warmup: int) -> dict:
    """Interleaved timing: key -> stage -> list of ms (plus 'total'). Says on stderr what it does:
    the warm-up (the first call of a jitted chain compiles it) and a bar over the repeats."""
    def run(steps, sink=None):
        x, total = None, 0.0
        for stage, fn in steps:
            t0 = time.perf_counter()
            x = fn(x)
            ms = 1e3 * (time.perf_counter() - t0)
            total += ms
            if sink is not None:
                sink[stage].append(ms)
        if sink is not None:
            sink["total"].append(total)

    with progress.stage(f"warming up {len(chains)} chain{'s' * (len(chains) > 1)} x {warmup} "
                        "(the first call compiles)", enabled=warmup > 0):
        for steps in chains.values():
            for _ in range(warmup):
                run(steps)
    samples = {k: {s: [] for s, _ in steps} | {"total": []} for k, steps in chains.items()}
    for _ in tqdm(range(repeats), desc=f"timing {len(chains)} chains, interleaved", unit="repeat",
                  disable=progress.quiet(), file=sys.stderr):
        for key, steps in chains.items():
            run(steps, samples[key])
    return samples

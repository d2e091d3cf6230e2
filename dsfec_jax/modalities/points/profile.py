"""What the profiler does differently for point-cloud models (DSFEC, RadarNeXt): their stages.

- Params and GFLOPs are grouped by `stage_of`: stem, stage1..4 (a stage's blocks share the prefix
  before '_'), neck, heads (every head), pillar_net; other top-level modules as they are.
- Latency stages (LATENCY_STAGES): pillar_net (the `encode` method: pillar feature net and
  scatter), backbone, neck_heads (the `detect` method), each on the previous stage's output.
"""

from __future__ import annotations

import jax

LATENCY_STAGES = ("pillar_net", "backbone", "neck_heads")


def stage_of(path: tuple[str, ...]) -> str:
    """Group a module path into the profiler's stages."""
    top = path[0] if path else "?"
    if top.startswith("stem"):
        return "stem"
    if top.startswith("stage"):
        return top.split("_")[0]
    if top.startswith("head"):
        return "heads"
    return top


def latency_stages(detector, variables, inputs) -> dict:
    """Jitted stage callables (not blocking; profile/latency.py wraps them): LATENCY_STAGES."""
    enc = jax.jit(lambda v, x: detector.apply_method(v, "encode", x["points"], x["mask"], x["coords"]))
    bb = jax.jit(lambda v, img: detector.apply_method(v, "backbone", img))
    det = jax.jit(lambda v, st: detector.apply_method(v, "detect", st))
    image = enc(variables, inputs)
    stages = bb(variables, image)
    return {"pillar_net": lambda: enc(variables, inputs), "backbone": lambda: bb(variables, image),
            "neck_heads": lambda: det(variables, stages)}

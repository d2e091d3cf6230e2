"""What the profiler does differently for camera models (Shuffle-YOLOv3, YOLOv3): their latency
stages (LATENCY_STAGES): features (the backbone), then head (the YOLOv3 FPN and its output convs on
those features), models/camera/net.py's stage methods. Params and GFLOPs are grouped by the
network's top-level parts (backbone, head: profile/counting.part_of)."""

from __future__ import annotations

import jax

LATENCY_STAGES = ("features", "head")


def latency_stages(detector, variables, inputs) -> dict:
    """Jitted stage callables (not blocking; profile/latency.py wraps them): LATENCY_STAGES."""
    feats_fn = jax.jit(lambda v, x: detector.apply_method(v, "features", x["image"]))
    head_fn = jax.jit(lambda v, f: detector.apply_method(v, "head_outputs", f))
    feats = feats_fn(variables, inputs)
    return {"features": lambda: feats_fn(variables, inputs), "head": lambda: head_fn(variables, feats)}

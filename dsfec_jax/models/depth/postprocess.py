"""monodepth's post-processing (monodepth_main.py post_process_disparity; paper §4.2 "post-processing").

The network sees the image and its mirror. The mirror's left-view disparity, flipped back, is
another estimate of the same map whose occlusion artefacts (the "disocclusion" ramp at the left
edge of the image and at the left of objects) fall on the other side. The blend takes the
mirror's estimate on the left 5 % of the width, the plain estimate on the right 5 %, and their
mean in between, with linear ramps 5 % wide:
    l = column position in [0, 1] (linspace(0, 1, W)),
    l_mask = 1 - clip(20 (l - 0.05), 0, 1),   r_mask = l_mask mirrored,
    out = r_mask * d + l_mask * d_flip + (1 - l_mask - r_mask) * (d + d_flip) / 2
with d the image's left disparity and d_flip the mirror's, flipped back.
"""

from __future__ import annotations

import jax.numpy as jnp

RAMP_SLOPE = 20.0   # the ramp reaches 0 at 0.05 + 1 / 20 = 10 % of the width
RAMP_START = 0.05


def ramp_masks(width: int):
    """(l_mask, r_mask), each (width,): weights of the mirror's and of the plain estimate."""
    l = jnp.linspace(0.0, 1.0, width)
    l_mask = 1.0 - jnp.clip(RAMP_SLOPE * (l - RAMP_START), 0.0, 1.0)
    return l_mask, l_mask[::-1]


def post_process_disparity(disp, disp_of_mirror):
    """Blend (..., H, W) disparity maps of an image and of its mirror (the latter as the network
    gave it, not yet flipped back) -> (..., H, W)."""
    if disp.shape != disp_of_mirror.shape:
        raise ValueError(f"post_process_disparity: shapes {disp.shape} and {disp_of_mirror.shape} differ")
    flipped = disp_of_mirror[..., ::-1]
    l_mask, r_mask = ramp_masks(disp.shape[-1])
    mean = 0.5 * (disp + flipped)
    return r_mask * disp + l_mask * flipped + (1.0 - l_mask - r_mask) * mean

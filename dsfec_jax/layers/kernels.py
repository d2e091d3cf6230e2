"""Which formulation a layer trains with: "fast", the ones chosen for XLA's CPU training step
(1x1 convs as matmuls, hand-written depthwise, conv-kernel and batch-norm gradients, sub-pixel
upsampling), or "plain", the textbook ones (lax.conv, autodiff, lax.conv_transpose). Same
parameters and the same values: tests hold the gradients equal, and
`dsfec bench --train --compare kernels=plain` measures the difference."""

from __future__ import annotations

from typing import Literal

Kernels = Literal["fast", "plain"]
KERNELS = ("fast", "plain")


def check_kernels(kernels: str) -> str:
    if kernels not in KERNELS:
        raise ValueError(f"kernels={kernels!r}; valid: {', '.join(map(repr, KERNELS))}")
    return kernels

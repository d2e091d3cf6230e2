"""Which formulation a layer trains with: "fast", the hand-written ones chosen for XLA's CPU
training step (1x1 convs as matmuls, hand-written depthwise, conv-kernel and batch-norm
gradients, sub-pixel upsampling, the numba depthwise kernel gradient), "plain", the textbook
ones (lax.conv, autodiff, lax.conv_transpose), or "auto" (every config's default): "fast" on the
backend they were measured on (the CPU), "plain" elsewhere. Same parameters and the same values:
tests hold the gradients equal, and `dsfec bench --train --compare kernels=plain` measures the
difference.

The environment variable DSFEC_KERNELS=off (or =xla) turns every hand-written kernel off,
whatever the configs say: the numba gradient reads XLA's call frame at hand-coded offsets
(depthwise_grad_cpu.py), so a user must be able to run without it. It is read when a layer is
traced, so set it before the process starts (a jitted function keeps the form it was traced with).
"""

from __future__ import annotations

import os
from typing import Literal

import jax

Kernels = Literal["auto", "fast", "plain"]
KERNELS = ("auto", "fast", "plain")
SWITCH = "DSFEC_KERNELS"
SWITCH_OFF = ("off", "xla")  # DSFEC_KERNELS values that turn the hand-written kernels off
MEASURED_ON = "cpu"  # the backend the hand-written kernels were chosen and measured on


def check_kernels(kernels: str) -> str:
    if kernels not in KERNELS:
        raise ValueError(f"kernels={kernels!r}; valid: {', '.join(map(repr, KERNELS))}")
    return kernels


def switched_off() -> bool:
    """Whether DSFEC_KERNELS turns every hand-written kernel off; unset or 'auto' leaves the
    choice to each layer's `kernels`."""
    value = os.environ.get(SWITCH, "").strip().lower()
    if value in ("", "auto"):
        return False
    if value in SWITCH_OFF:
        return True
    raise ValueError(f"{SWITCH}={os.environ[SWITCH]!r}; valid: unset or 'auto' (each config's `kernels` "
                     f"decides), {' or '.join(map(repr, SWITCH_OFF))} (every hand-written kernel off)")


def hand_written(kernels: str) -> bool:
    """Whether a layer with this `kernels` runs the hand-written formulations: "fast" does, "plain"
    never, "auto" on the backend they were measured on; none of them with DSFEC_KERNELS=off."""
    check_kernels(kernels)
    if switched_off():
        return False
    return kernels == "fast" or (kernels == "auto" and jax.default_backend() == MEASURED_ON)

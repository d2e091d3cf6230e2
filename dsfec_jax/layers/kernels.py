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

`observed_decisions()` collects every choice `hand_written` makes while it is open, with the backend
it read: the device check (profile/device_check) reports from them which formulation each traced
program took, and refuses "auto" having chosen the fast kernels for another backend than MEASURED_ON.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from typing import Iterator, Literal

import jax

Kernels = Literal["auto", "fast", "plain"]
KERNELS = ("auto", "fast", "plain")
SWITCH = "DSFEC_KERNELS"
SWITCH_OFF = ("off", "xla")  # DSFEC_KERNELS values that turn the hand-written kernels off
MEASURED_ON = "cpu"  # the backend the hand-written kernels were chosen and measured on


@dataclasses.dataclass(frozen=True)
class Decision:
    """One layer's choice while a program was traced: its `kernels`, the backend `hand_written`
    read (jax.default_backend()) and whether it took the hand-written formulation."""

    kernels: str
    backend: str
    fast: bool


_observers: list[list[Decision]] = []  # the logs of the open observed_decisions() blocks


@contextlib.contextmanager
def observed_decisions() -> Iterator[list[Decision]]:
    """A list that collects each hand_written decision made (at trace time) until the block ends."""
    log: list[Decision] = []
    _observers.append(log)
    try:
        yield log
    finally:
        _observers.remove(log)


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
    backend = jax.default_backend()
    fast = not switched_off() and (kernels == "fast" or (kernels == "auto" and backend == MEASURED_ON))
    for log in _observers:
        log.append(Decision(kernels, backend, fast))
    return fast

"""Per-step losses kept on the device and read together, so a loop does not wait for every step.

JAX dispatches a jitted step asynchronously and returns arrays that are still being computed
(https://docs.jax.dev/en/latest/async_dispatch.html); `float(loss)` waits for the step to end. A
loop that reads every loss therefore stops the host until each step is done, and the next step
cannot be queued meanwhile. Here a loop hands each step's loss over (`add`) and reads them all
only when it needs a value (`check`: at a log, evaluation or checkpoint step), which raises for
the first non-finite one, naming its step.

`add` keeps at most IN_FLIGHT steps queued: it waits for the step before the one just queued,
so the device always has the next step to run while the host prepares another, and a host
faster than the device cannot queue many steps' inputs in memory.
"""

from __future__ import annotations

import math

import jax

IN_FLIGHT = 2  # steps queued on the device at once: the one running and the next


class NonFiniteLoss(FloatingPointError):
    def __init__(self, step: int, value: float):
        super().__init__(f"loss is {value} at step {step}")
        self.step, self.value = step, value


class LossWatch:
    """Losses of the steps since the last `check`, as device arrays."""

    def __init__(self):
        self._pending: list[tuple[int, jax.Array]] = []

    def add(self, step: int, loss: jax.Array) -> None:
        """Record step `step`'s loss (not read now); wait until at most IN_FLIGHT steps are queued."""
        self._pending.append((step, loss))
        if len(self._pending) >= IN_FLIGHT:
            jax.block_until_ready(self._pending[-IN_FLIGHT][1])

    def check(self) -> float | None:
        """The latest loss as a float (None when none was added since the last check). Raises
        NonFiniteLoss for the first non-finite loss since the last check."""
        pending, self._pending = self._pending, []
        values = jax.device_get([loss for _, loss in pending])
        for (step, _), value in zip(pending, values):
            if not math.isfinite(float(value)):
                raise NonFiniteLoss(step, float(value))
        return float(values[-1]) if values else None
